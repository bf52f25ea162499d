//! The Python of the test suite's virtual environment (FMPy, numpy, scipy, pythonfmu).

use std::path::PathBuf;

/// `TWINBENCH_PYTHON`, or `target/venv/bin/python`; a clear failure (not a skip) when absent.
pub fn python() -> PathBuf {
    if let Ok(p) = std::env::var("TWINBENCH_PYTHON") {
        return PathBuf::from(p);
    }
    let p = twinbench::pack::workspace_root().join("target/venv/bin/python");
    assert!(
        p.exists(),
        "{} not found: create it with `python3 -m venv target/venv && target/venv/bin/pip install -r tools/requirements.txt` (the README's test command does)",
        p.display()
    );
    p
}
