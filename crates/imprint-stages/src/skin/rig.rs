//! Rigs: bones, rest pose, animation, and the pose at a time (filled in by the rig work).
