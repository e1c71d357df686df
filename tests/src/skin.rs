//! Skinning test pieces shared by the skinning tests (filled in by the rig work).
