//! Volume, cross-section and self-intersection measures of skinned meshes (filled in by the rig work).
