# The third-party sources the test suite builds, pinned (sourced by tools/test.sh and
# tools/omsimulator.sh; README, "What the tests need").
#
# The Modelica Reference FMUs (2-Clause BSD): the importer's conformance suite, built by the
# tests with gcc. A git commit names its content exactly.
REFERENCE_FMUS_REPOSITORY=https://github.com/modelica/Reference-FMUs
REFERENCE_FMUS_COMMIT=1258711a41e28b1c25e058abd04f6214beefa3cb
# OMSimulator 3.0 (OSMC licence) for the host tests, built once per machine from its source
# archive: v3.0.0.post114, commit acb56d9d with its pinned OMSimulator-3rdParty 1168b8e.
# Its PyPI package downloads binaries at install time from a host CI cannot reach, and no
# Debian package exists, so it is built from sources.
OMSIMULATOR_REPOSITORY=https://github.com/OpenModelica/OMSimulator
OMSIMULATOR_COMMIT=acb56d9d
OMSIMULATOR_3RDPARTY_COMMIT=1168b8e
OMSIMULATOR_ARCHIVE=OMSimulator-v3.0.0.post114-src.tar.gz
OMSIMULATOR_SHA256=ce818cc4cde71c216b63e59b40033c4f5cf52306d57f5348fad5ee001867a6ca
