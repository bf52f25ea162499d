#!/usr/bin/env bash
# Every workspace member builds on its own, with only the features its own manifest asks
# for (a workspace build unifies features and can hide a missing one): `cargo check -p X
# --all-targets` for each, then `cargo test -p X` for each library crate (the root crate's
# tests are tools/test.sh's fast tier). Needs the environment tools/test.sh sets up.
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-check}"
members=$(cargo metadata --no-deps --format-version 1 \
    | python3 -c 'import json,sys; print("\n".join(p["name"] for p in json.load(sys.stdin)["packages"]))')
for p in $members; do
    case "$mode" in
    check)
        echo "== cargo check -p $p --all-targets"
        cargo check --quiet --release -p "$p" --all-targets
        ;;
    test)
        [ "$p" = twinbench ] && continue
        echo "== cargo test -p $p"
        cargo test --quiet --release -p "$p"
        ;;
    esac
done
