#!/usr/bin/env python3
"""The house's measures (docs/design.md, "Measured"): the sizes and error types a maintainer
reads before changing code, counted over the tracked Rust files of the checkout.

- functions over 100 lines, tests excluded (files under a `tests/` folder, `tests.rs`, and
  the `#[cfg(test)]` module at the end of a file), by brace matching: from the `fn` line to
  the closing brace at the same indentation;
- files over 1,000 lines (every tracked `.rs` file, tests included);
- `Result<_, String>` in the signatures of the library crates (`crates/`, `models/`),
  tests excluded;
- the tests' checks of an error's kind: `matches!(` against a variant (a call of a test
  helper `fn …(…) -> bool` whose body is such a `matches!` counts as one, the helper's own
  `matches!` not), and single-line
  `assert!(... .contains(...))` on the message of an error value the test got in-process
  (`unwrap_err()`, `Err(e)`, `.err()`); the other single-line contains-asserts (a command's
  stderr, an FMU's log, a report, a file: text a user reads, where the wording is the
  point) are counted apart. A call of the phrase-list helper `assert_contains(text, &[..])`
  (tb-testkit) counts once, as one such assert, by the same rule on its first argument.
  The helpers' own crate (`crates/testkit`) is not counted: its tests test the helpers;
- circles of imports between the files of one crate (`use crate::…`, `use super::…`, and
  paths written out in the code), tests excluded: files that import each other, directly or
  round a loop. A module's `mod` and `pub use` lines count as imports of the file that
  re-exports (a file that only declares its children is no circle with them).

Usage: tools/house.py [--json] [--list]   (from anywhere in the checkout)
"""
import argparse
import json
import os
import re
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FN = re.compile(r'^(\s*)(pub(\([a-z:]+\))? )?(const )?(unsafe )?(async )?(extern "C" )?fn (\w+)')


def tracked():
    out = subprocess.check_output(["git", "ls-files", "*.rs"], cwd=ROOT, text=True)
    return [p for p in out.split() if os.path.exists(os.path.join(ROOT, p))]


def is_test_file(p):
    return "/tests/" in p or p.startswith("tests/") or p.endswith("/tests.rs") or p == "tests.rs"


def code_lines(p):
    """The file's lines up to its test module (`#[cfg(test)]` followed by `mod`)."""
    lines = open(os.path.join(ROOT, p), encoding="utf-8").read().split("\n")
    for i, l in enumerate(lines):
        if l.strip() == "#[cfg(test)]" and i + 1 < len(lines) and re.match(r"\s*(pub )?mod \w+", lines[i + 1]):
            return lines[:i]
    return lines


def long_functions(files, limit=100):
    found = []
    for p in files:
        if is_test_file(p):
            continue
        lines = code_lines(p)
        for i, l in enumerate(lines):
            m = FN.match(l)
            if not m:
                continue
            # A declaration without a body (a trait's, an `extern` block's), on one line or
            # several: its signature ends with `;` before any `{`.
            k = i
            while k < len(lines) and not lines[k].rstrip().endswith(("{", ";")):
                k += 1
            if k < len(lines) and lines[k].rstrip().endswith(";"):
                continue
            ind = len(m.group(1))
            j = i + 1
            while j < len(lines) and not (
                lines[j].startswith(" " * ind + "}")
                and (len(lines[j]) == ind + 1 or lines[j][ind + 1] in " ;),")
            ):
                j += 1
            n = j - i + 1
            if n > limit:
                found.append((n, p, i + 1, m.group(8)))
    return sorted(found, reverse=True)


def long_files(files, limit=1000):
    out = []
    for p in files:
        n = sum(1 for _ in open(os.path.join(ROOT, p), encoding="utf-8"))
        if n > limit:
            out.append((n, p))
    return sorted(out, reverse=True)


def string_results(files):
    pat = re.compile(r"Result<[^<>]*(<[^<>]*>)?[^<>]*,\s*String>")
    out = []
    for p in files:
        if is_test_file(p) or not (p.startswith("crates/") or p.startswith("models/")):
            continue
        if p.startswith("crates/python/") or p.startswith("crates/testkit/"):
            continue
        for i, l in enumerate(code_lines(p)):
            if pat.search(l):
                out.append((p, i + 1))
    return out


ERROR_SOURCE = re.compile(r"unwrap_err\(|expect_err\(|\bErr\(|\.err\(\)|\.unwrap_err|_err\(")
CONTAINS = re.compile(r"assert!\((.*?)\.contains\(")


def error_helpers(text):
    """The file's helper functions that return the message of an error the test got
    in-process (`fn error_of(..) -> String { ... unwrap_err() ... }`): their calls count as
    such a message. One that reads a command's stderr does not."""
    helpers = set()
    for m in re.finditer(r"\n\s*(?:pub )?fn (\w+)\([^)]*\)[^{]*\{", text):
        body = text[m.end() : m.end() + 1500]
        end = re.search(r"\n(\s*)\}\n", body)
        body = body[: end.start()] if end else body
        if ERROR_SOURCE.search(body) and "stderr" not in body:
            helpers.add(m.group(1))
    return helpers


ASSERT_CONTAINS = re.compile(r"(?<![\w:])(?<!fn )assert_contains\(")


def assert_contains_subject(lines, i):
    """The first argument of the `assert_contains(` call on line i (the call may span
    lines), or None."""
    m = ASSERT_CONTAINS.search(lines[i])
    if not m:
        return None
    rest = lines[i][m.end() :] + " " + " ".join(l.strip() for l in lines[i + 1 : i + 4])
    depth = 0
    for k, c in enumerate(rest):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            if depth == 0:
                return rest[:k].strip()
            depth -= 1
        elif c == "," and depth == 0:
            return rest[:k].strip()
    return None


def message_of_an_error(lines, i, helpers=frozenset(), subject=None):
    """Whether the `assert!(x.contains(...))` on line i (or the `assert_contains(x, ..)`
    whose first argument is `subject`) reads the message of an error value the test got
    in-process (`unwrap_err()`, `Err(e)`, `.err()`, or a helper of the file that returns
    one): a check of the error's kind by its text. Text a user reads (a command's stderr,
    an FMU's log, a report, a file) is not: there the message is the point."""
    if subject is None:
        m = CONTAINS.search(lines[i])
        if not m:
            return False
        subject = m.group(1)
    calls = set(re.findall(r"(\w+)\(", subject))
    if ERROR_SOURCE.search(subject) or calls & helpers:
        return True
    name = re.match(r"\s*&?\(?\s*(\w+)", subject)
    if not name:
        return False
    var = name.group(1)
    # The binding of `var` in the lines before (its statement may span lines).
    for j in range(i - 1, max(-1, i - 25), -1):
        if re.search(r"\blet (mut )?\(?[\w, ]*\b%s\b" % re.escape(var), lines[j]) or re.search(
            r"Err\(%s\)" % re.escape(var), lines[j]
        ):
            stmt = " ".join(lines[j : i]).split(";")[0]
            return bool(ERROR_SOURCE.search(stmt) or set(re.findall(r"(\w+)\(", stmt)) & helpers)
    return False


def assert_statement(lines, i):
    """The `assert!(` statement that starts on line i, joined (at most 8 lines)."""
    out = []
    for l in lines[i : i + 8]:
        out.append(l.strip())
        if l.rstrip().endswith(");"):
            break
    return " ".join(out)


VARIANT_HELPER = re.compile(r"\n\s*(?:pub(?:\([a-z]+\))? )?fn (\w+)\([^)]*\)\s*->\s*bool\s*\{")


def variant_helper_bodies(text):
    """The helpers of a test file that check an error's kind (`fn refused(e: &E, …) -> bool
    { matches!(…) }`): (name, start, end) of each, the span from `fn` to its closing
    brace."""
    out = []
    for m in VARIANT_HELPER.finditer(text):
        body = text[m.end() : m.end() + 2000]
        end = re.search(r"\n\s*\}\n", body)
        stop = m.end() + (end.end() if end else len(body))
        if re.search(r"matches!\(", text[m.end() : stop]):
            out.append((m.group(1), m.start(), stop))
    return out


def variant_helpers(text):
    """{name: 1} for each variant helper of the file (a call counts as one check)."""
    return {name: 1 for name, _, _ in variant_helper_bodies(text)}


def shared_test_helpers(files):
    """The variant helpers of the test support modules (`tests/common/`, a crate's
    `tests/support/`): {module name: {helper name: 1}}, for the test files that import
    them."""
    helpers = {}
    for p in files:
        if ("/common/" in "/" + p or "/support/" in p) and is_test_file(p):
            found = variant_helpers(open(os.path.join(ROOT, p), encoding="utf-8").read())
            if found:
                module = os.path.splitext(os.path.basename(p))[0]
                if module == "mod":
                    module = os.path.basename(os.path.dirname(p))
                helpers.setdefault(module, {}).update(found)
    return helpers


def imported(text, shared):
    """The shared variant helpers `text` imports (`use …::kinds::{refused, …}`) or calls by
    their module (`kinds::refused(`)."""
    out = {}
    for module, names in shared.items():
        uses = " ".join(re.findall(r"use [\w:]*\b%s::([^;]*);" % re.escape(module), text))
        for name in names:
            if re.search(r"\b%s\b" % re.escape(name), uses) or "%s::%s(" % (module, name) in text:
                out[name] = 1
    return out


def variant_checks(text, helpers):
    """`matches!(` in `text` outside the bodies of the variant helpers it defines, plus a
    call of a helper (its own or a shared one) each, also outside those bodies: a helper
    built on another counts once, where a test calls it."""
    spans = variant_helper_bodies(text)
    for _, start, stop in reversed(spans):
        text = text[:start] + text[stop:]
    n = len(re.findall(r"matches!\(", text))
    for name in helpers:
        n += len(re.findall(r"(?<![\w.])(?<!fn )%s\(" % re.escape(name), text))
    return n


def kind_checks(files):
    """(matches! against a variant, contains-asserts on an error's message, all other
    contains-asserts on text) as review 5 counted them (an assert on one line), and the
    two contains counts again over every contains-assert, one spread over lines
    included."""
    variant = message = other = message_all = other_all = 0
    shared = shared_test_helpers(files)
    for p in files:
        if p.startswith("crates/testkit/"):
            continue
        text = open(os.path.join(ROOT, p), encoding="utf-8").read()
        if not is_test_file(p):
            i = text.find("#[cfg(test)]")
            if i < 0:
                continue
            text = text[i:]
        variant += variant_checks(text, {**imported(text, shared), **variant_helpers(text)})
        lines = text.split("\n")
        helpers = error_helpers(open(os.path.join(ROOT, p), encoding="utf-8").read())
        for i, l in enumerate(lines):
            one_line = subject = None
            if re.search(r"assert!\([^\n]*\.contains\(", l):
                one_line = True
                subject = CONTAINS.search(l).group(1)
            elif re.search(r"(?<![\w:])assert!\(\s*$", l):
                m = CONTAINS.search(assert_statement(lines, i))
                if m:
                    one_line, subject = False, m.group(1)
            else:
                subject = assert_contains_subject(lines, i)
                if subject is not None:
                    one_line = ");" in l[ASSERT_CONTAINS.search(l).end() :]
            if subject is None:
                continue
            of_error = message_of_an_error(lines, i, helpers, subject)
            message_all += of_error
            other_all += not of_error
            if one_line:
                message += of_error
                other += not of_error
    return variant, message, other, message_all, other_all



def crate_of(p):
    """(crate root folder, source folder) of a tracked file, or None."""
    parts = p.split("/")
    if "src" not in parts:
        return None
    i = parts.index("src")
    return "/".join(parts[:i]), "/".join(parts[: i + 1])


def module_file(src, segments):
    """The file of a module path below `src`, the longest prefix that names a file."""
    for n in range(len(segments), 0, -1):
        base = os.path.join(src, *segments[:n])
        for cand in (base + ".rs", os.path.join(base, "mod.rs")):
            if os.path.exists(os.path.join(ROOT, cand)):
                return cand
    return None


def module_path(src, p):
    rel = os.path.relpath(p, src)[:-3].split("/")
    if rel[-1] in ("mod", "lib", "main"):
        rel = rel[:-1]
    return rel


# `$crate::` in a macro is resolved where the macro is used: no import of this file.
PATH = re.compile(r"(?<!\$)\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")


def circles(files):
    """Strongly connected groups of more than one file, per crate."""
    edges = {}
    for p in files:
        if is_test_file(p) or not p.endswith(".rs"):
            continue
        c = crate_of(p)
        if not c:
            continue
        _, src = c
        here = module_path(src, p)
        text = "\n".join(code_lines(p))
        text = re.sub(r"//[^\n]*", "", text)
        targets = set()
        for m in PATH.finditer(text):
            segs = m.group(2).split("::")[1:]
            if m.group(1) == "crate":
                base = []
            else:
                base = list(here)
                # `super` of a file `a/b.rs` (module a::b) is `a`; of `a/mod.rs` too.
                rest = m.group(2).split("::")[1:]
                base = base[:-1]
                while rest and rest[0] == "super":
                    base = base[:-1]
                    rest = rest[1:]
                segs = rest
            f = module_file(src, base + segs)
            if f and f != p:
                targets.add(f)
        edges[p] = targets
    # Tarjan's strongly connected components.
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in edges:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    import sys
    sys.setrecursionlimit(10000)
    for v in list(edges):
        if v not in index:
            visit(v)
    return out

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--list", action="store_true", help="name every long function, long file and String error")
    a = ap.parse_args()
    files = tracked()
    fns, big, strs = long_functions(files), long_files(files), string_results(files)
    variant, message, other, message_all, other_all = kind_checks(files)
    loops = circles(files)
    result = {
        "functions_over_100_lines": len(fns),
        "files_over_1000_lines": len(big),
        "result_string_in_library_crates": len(strs),
        "tests_matching_a_variant": variant,
        "tests_matching_an_error_message": message,
        "tests_matching_other_text": other,
        "tests_matching_an_error_message_any_layout": message_all,
        "tests_matching_other_text_any_layout": other_all,
        "circles_inside_crates": len(loops),
        "files_in_the_largest_circle": max((len(c) for c in loops), default=0),
    }
    if a.json:
        if a.list:
            result["functions"] = [f"{p}:{line} {name} {n}" for n, p, line, name in fns]
            result["files"] = [f"{p} {n}" for n, p in big]
            result["circles"] = loops
        print(json.dumps(result, indent=1))
        return
    for k, v in result.items():
        print(f"{k.replace('_', ' ')}: {v}")
    if a.list:
        for n, p, line, name in fns:
            print(f"  fn {p}:{line} {name}: {n} lines")
        for n, p in big:
            print(f"  file {p}: {n} lines")
        for c in loops:
            print(f"  circle: {', '.join(c)}")
        by_crate = {}
        for p, _ in strs:
            c = "/".join(p.split("/")[:2])
            by_crate[c] = by_crate.get(c, 0) + 1
        for c, n in sorted(by_crate.items(), key=lambda x: -x[1]):
            print(f"  Result<_, String> in {c}: {n}")


if __name__ == "__main__":
    main()
