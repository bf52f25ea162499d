//! twinbench dyno model (to be written).
