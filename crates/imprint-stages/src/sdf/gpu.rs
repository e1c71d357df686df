//! GPU distance field: written by the GPU work.
