//! Line plots (to be written).
