#!/usr/bin/env bash
# The CVODE binding's tests (crates/fmi/src/import/model_exchange/cvode.rs) under valgrind's
# memcheck: every read and write through the FFI, CVODE's own included, checked; an invalid
# access or a definitely lost block fails. (Miri cannot run them: CVODE is C.)
set -euo pipefail
cd "$(dirname "$0")/.."
tools/valgrind.sh
bin=$(cargo test --release -p tb-fmi --lib --no-run --message-format=json 2>/dev/null \
    | python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "tb_fmi" and m.get("executable"):
        print(m["executable"])')
valgrind --tool=memcheck --error-exitcode=9 --leak-check=full --errors-for-leak-kinds=definite --show-leak-kinds=definite \
    --quiet "$bin" --test-threads=1 model_exchange::cvode
