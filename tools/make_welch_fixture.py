#!/usr/bin/env python3
"""Write the Welch/H1 reference fixture for tb-analysis with scipy.signal.

The input is fixed (seeded white noise through a dead time + first-order lag, plus a
little output noise) and stored in the fixture itself, so the Rust tests need no Python
and do not depend on numpy's random generator. Re-run only to regenerate:

    python tools/make_welch_fixture.py [OUT.json]

Default output: crates/analysis/tests/fixtures/welch_scipy.json
"""
import json
import os
import sys

import numpy as np
import scipy
import scipy.signal as sig


def main() -> None:
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(__file__), "..", "crates", "analysis", "tests", "fixtures", "welch_scipy.json")
    fs = 10_000.0
    n = 4096
    rng = np.random.default_rng(20240611)
    u = rng.standard_normal(n)
    # y: dead time of 5 samples, then a discrete first-order lag (T = 1 ms), plus noise
    dt = 1.0 / fs
    a = np.exp(-dt / 1e-3)
    delayed = np.concatenate([np.zeros(5), u[:-5]])
    y = sig.lfilter([1.0 - a], [1.0, -a], delayed) + 0.05 * rng.standard_normal(n) + 0.3
    cases = []
    for nperseg, noverlap, detrend in [(256, 128, False), (200, 50, "constant"), (255, None, "constant")]:
        kw = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=noverlap, detrend=detrend,
                  scaling="density", return_onesided=True)
        f, puu = sig.welch(u, **kw)
        _, pyy = sig.welch(y, **kw)
        _, puy = sig.csd(u, y, **kw)
        _, coh = sig.coherence(u, y, **{k: v for k, v in kw.items() if k not in ("scaling", "return_onesided")})
        h1 = puy / puu
        cases.append({
            "nperseg": nperseg,
            "noverlap": noverlap if noverlap is not None else nperseg // 2,
            "detrend": "none" if detrend is False else detrend,
            "freq": f.tolist(),
            "puu": puu.tolist(),
            "pyy": pyy.tolist(),
            "puy_re": puy.real.tolist(),
            "puy_im": puy.imag.tolist(),
            "h1_re": h1.real.tolist(),
            "h1_im": h1.imag.tolist(),
            "coherence": coh.tolist(),
        })
    doc = {
        "generator": "tools/make_welch_fixture.py",
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "fs": fs,
        "u": u.tolist(),
        "y": y.tolist(),
        "cases": cases,
    }
    with open(out, "w") as fh:
        json.dump(doc, fh)
        fh.write("\n")
    print(f"wrote {out}: {n} samples, {len(cases)} cases")


if __name__ == "__main__":
    main()
