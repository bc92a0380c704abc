//! Calibration files (placeholder: being written).
