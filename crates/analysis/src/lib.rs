//! twinbench analysis (to be written).
