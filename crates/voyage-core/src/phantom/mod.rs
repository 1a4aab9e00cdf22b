//! Synthetic phantoms with ground truth (in progress).
