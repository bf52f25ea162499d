#!/usr/bin/env python3
"""Build the pythonfmu supplier EDU into target/fmu/supplier_edu.fmu (part of tools/test.sh).

Run it with the Python whose pythonfmu builds the FMU and whose libpython runs it
(target/venv/bin/python):

    target/venv/bin/python tools/supplier_edu/build.py [--dest DIR]

Besides the FMU it writes DIR/libpython.so, a symbolic link to that Python's shared
libpython: a native host must load it with RTLD_GLOBAL before the FMU (pythonfmu's
binary does not link it), and systems/rls_v_supplier.toml names it in `preload`.
"""

import argparse
import os
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
MODEL = HERE / "supplier_edu.py"
FMU_NAME = "supplier_edu.fmu"
LIBPYTHON_LINK = "libpython.so"


def libpython() -> Path:
    """The shared libpython of this interpreter (fails when Python was built static)."""
    cfg = sysconfig.get_config_var
    if not cfg("Py_ENABLE_SHARED"):
        sys.exit(
            f"{sys.executable}: this Python has no shared libpython (built without "
            "--enable-shared); a native host cannot run pythonfmu FMUs with it. Use a Python "
            "with libpython3.x.so (distribution packages and pyenv with "
            "PYTHON_CONFIGURE_OPTS=--enable-shared have one)."
        )
    names = [n for n in (cfg("INSTSONAME"), cfg("LDLIBRARY")) if n]
    dirs = [d for d in (cfg("LIBDIR"), cfg("LIBPL")) if d]
    if cfg("LIBDIR") and cfg("MULTIARCH"):
        dirs.append(os.path.join(cfg("LIBDIR"), cfg("MULTIARCH")))
    for d in dirs:
        for n in names:
            p = Path(d) / n
            if p.exists():
                return p.resolve()
    sys.exit(f"libpython not found: looked for {names} in {dirs}")


def check(fmu: Path) -> None:
    """The post-processed model description declares every unit it uses and is valid."""
    with zipfile.ZipFile(fmu) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
    defined = {u.get("name") for u in root.iter("Unit")}
    used = {r.get("unit") for r in root.iter("Real") if r.get("unit")}
    if not used or not used <= defined:
        sys.exit(f"{fmu}: units used {sorted(used)} but defined {sorted(defined)}")
    try:
        from fmpy.validation import validate_fmu
    except ImportError:
        return  # FMPy (tools/requirements.txt) is the second opinion when present
    problems = validate_fmu(str(fmu))
    if problems:
        sys.exit(f"{fmu}: FMPy finds the model description invalid: {problems}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dest", type=Path, default=ROOT / "target" / "fmu")
    args = ap.parse_args()
    dest = args.dest.resolve()
    dest.mkdir(parents=True, exist_ok=True)
    lib = libpython()
    # Build into a temporary file and rename: other test runs may read the FMU meanwhile.
    with tempfile.TemporaryDirectory(dir=dest, prefix=".supplier_edu-") as tmp:
        out = Path(tmp) / FMU_NAME
        subprocess.run(
            [sys.executable, "-m", "pythonfmu", "build", "-f", str(MODEL), "-d", str(out)],
            check=True,
            cwd=tmp,
            stdout=subprocess.DEVNULL,
        )
        check(out)
        os.replace(out, dest / FMU_NAME)
        link = Path(tmp) / LIBPYTHON_LINK
        link.symlink_to(lib)
        os.replace(link, dest / LIBPYTHON_LINK)
    print(f"{dest / FMU_NAME} (preload {dest / LIBPYTHON_LINK} -> {lib})")


if __name__ == "__main__":
    main()
