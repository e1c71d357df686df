//! wgpu device handling: written by the GPU work.
