//! Linear blend and dual quaternion skinning (filled in by the rig work).
