//! twinbench vehicle model (to be written).
