//! twinbench edu model (to be written).
