//! twinbench compare (to be written).
