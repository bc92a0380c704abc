//! Video frames (placeholder: being written).
