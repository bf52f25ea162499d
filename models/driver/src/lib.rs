//! twinbench driver model (to be written).
