//! GPU voxelisation: written by the GPU work.
