#!/usr/bin/env python3
"""Point every reference to the model specification at ``docs/model.md``, and make checkout paths relative.

The specification lives in the repository as ``docs/model.md``; its sections keep the numbers §1-§10
that the code cites. This tool rewrites, in every tracked text file (``git ls-files``):

1. Markdown link targets to a specification file outside the repository (``](../<dir>/<SPEC>)``) to the
   relative path of ``docs/model.md`` from the linking file, and the same path in link labels or prose
   to ``docs/model.md``;
2. every other bare mention of the upper-case specification file name (``<SPEC> §6``, ``<SPEC>'s frame``,
   ``a port of <SPEC>``) to ``docs/model.md`` (so ``<SPEC> §N`` becomes ``docs/model.md §N``);
3. with ``--strip-issue-refs``: planning-issue references in parentheses, "(<issue> 4)", "(<issue> 5; X)" ->
   "(X)", "; <issue> \"Title\")" -> ")", "<issue> 4's target" -> "target" (<issue> = the word; other
   mentions are listed for a person to rewrite);
4. with ``--fix-wording``: the few sentences that the rewrite would make untrue, because they describe the
   old file ("<spec> §2 prints 0.0244221": docs/model.md §2 gives Table 4.1's value and says that
   Table B.3 prints 0.0244221) or how a port was made ("throwaway port" -> "independent port");
5. with ``--checkout-prefix PREFIX`` (repeatable): absolute paths ``PREFIX/<tracked path>`` written into
   generated files (training records, results) to the repository-relative ``<tracked path>``.

<SPEC> stands for the upper-case spelling of ``docs/model.md``'s file name. The patterns below escape the
dot, so this file does not mention the name itself (tests/test_repo_hygiene.py scans it too).

Usage (from the repository root)::

    python docs/tools/rewrite_model_refs.py                 # dry run: what would change, per file
    python docs/tools/rewrite_model_refs.py --write         # apply
    python docs/tools/rewrite_model_refs.py --write --strip-issue-refs --fix-wording \\
        --checkout-prefix /path/of/the/checkout/that/wrote/train/results

It prints the number of rewritten references per file and kind, then the lines a person should reread
because the sentence around a reference may describe the old file rather than ``docs/model.md``
(words such as "prints", "misprint", "typo", "deviation").
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

SPEC_TARGET = "docs/model.md"
_SPEC = r"MODEL\.md"
# ](../shared/SPEC) or ](../../x/SPEC#anchor): a Markdown link target outside the repository.
LINK_TARGET = re.compile(r"\]\((?P<path>(?:\.\./)+(?:[\w.-]+/)*" + _SPEC + r")(?P<anchor>#[^)]*)?\)")
# ../shared/SPEC in link labels, code spans and prose.
RELATIVE_PATH = re.compile(r"(?:\.\./)+(?:[\w.-]+/)*" + _SPEC)
# A bare SPEC not already part of a path or a longer name.
BARE = re.compile(r"(?<![\w/.-])" + _SPEC)
_ISSUE = r"[Ii]ssues?\s+#?\d+"
ISSUE_SUBS = [
    (re.compile(r"\s*\(" + _ISSUE + r"\)"), ""),
    (re.compile(r"\(" + _ISSUE + r";\s*"), "("),
    (re.compile(r";\s*[Ii]ssue\s+\"[^\"\n]+\"\)"), ")"),
    (re.compile(_ISSUE + r"'s\s+target"), "target"),
]
ISSUE_LEFT = re.compile(r"\b" + _ISSUE + r"|\b[Ii]ssues?\s+\"[^\"\n]+\"")
WORDING = [
    (re.compile(r"\ba throwaway port of docs/model\.md"), "an independent port of docs/model.md"),
    (re.compile(r"\bthrowaway port of docs/model\.md"), "independent port of docs/model.md"),
    (re.compile(r"docs/model\.md §2 misprints 0\.0244221"), "Table B.3 prints 0.0244221"),
    (re.compile(r"docs/model\.md §2 prints b_eff = 0\.0244221"), "Table B.3 prints b_eff = 0.0244221"),
]
REVIEW = re.compile(r"(?i)\b(misprint\w*|prints|printed|typo|deviation\w*|throwaway)\b")
TEXT_SUFFIXES = {".py", ".md", ".txt", ".yaml", ".yml", ".toml", ".json", ".ipynb", ".csv", ".cfg", ".ini", ""}


def tracked_files(root: Path) -> list[str]:
    """Tracked files of the git checkout at ``root`` (all files below it when it is not a checkout)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True).stdout
        return [p for p in out.decode().split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        return [str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and ".git" not in p.parts]


def read_text(path: Path) -> str | None:
    if path.suffix not in TEXT_SUFFIXES and path.name not in ("Makefile", "LICENSE"):
        return None
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def rewrite(text: str, rel: str, tracked: set[str], prefixes: list[str],
            strip_issues: bool = False, fix_wording: bool = False) -> tuple[str, Counter]:
    """Return the rewritten text of the file ``rel`` and the count of rewrites by kind."""
    counts: Counter = Counter()
    here = os.path.dirname(rel)
    link = os.path.relpath(SPEC_TARGET, here or ".")

    def link_sub(m):
        counts["link target"] += 1
        return f"]({link}{m.group('anchor') or ''})"

    def path_sub(m):
        counts["outside path"] += 1
        return SPEC_TARGET

    def bare_sub(m):
        counts["bare name"] += 1
        return SPEC_TARGET

    text = LINK_TARGET.sub(link_sub, text)
    text = RELATIVE_PATH.sub(path_sub, text)
    text = BARE.sub(bare_sub, text)
    if fix_wording:
        for pattern, repl in WORDING:
            text, n = pattern.subn(repl, text)
            if n:
                counts["wording"] += n
    if strip_issues:
        for pattern, repl in ISSUE_SUBS:
            text, n = pattern.subn(repl, text)
            counts["issue reference"] += n
        if not counts["issue reference"]:
            del counts["issue reference"]
    for prefix in prefixes:
        prefix = prefix.rstrip("/") + "/"
        pattern = re.compile(re.escape(prefix) + r"(?P<tail>[\w.+/-]+)")

        def abs_sub(m):
            tail = m.group("tail")
            if tail in tracked or any(t.startswith(tail.rstrip("/") + "/") for t in tracked):
                counts["checkout path"] += 1
                return tail
            return m.group(0)

        text = pattern.sub(abs_sub, text)
    return text, counts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, default=Path.cwd(), help="repository root (default: the current folder)")
    ap.add_argument("--write", action="store_true", help="apply the changes (default: dry run)")
    ap.add_argument("--checkout-prefix", action="append", default=[], metavar="PREFIX",
                    help="an absolute checkout path to strip from generated files (repeatable)")
    ap.add_argument("--strip-issue-refs", action="store_true", help="remove planning-issue references (see above)")
    ap.add_argument("--fix-wording", action="store_true", help="reword sentences about the old file (see above)")
    args = ap.parse_args(argv)
    root = args.root.resolve()
    files = tracked_files(root)
    tracked = set(files)
    total: Counter = Counter()
    review: list[str] = []
    left: list[str] = []
    for rel in sorted(files):
        path = root / rel
        if not path.is_file():
            continue
        text = read_text(path)
        if text is None:
            continue
        new, counts = rewrite(text, rel, tracked, args.checkout_prefix, args.strip_issue_refs, args.fix_wording)
        if args.strip_issue_refs:
            for k, line in enumerate(new.splitlines(), start=1):
                if ISSUE_LEFT.search(line):
                    left.append(f"{rel}:{k}: {line.strip()[:160]}")
        if new == text:
            continue
        total.update(counts)
        print(f"{rel}: " + ", ".join(f"{n} {kind}" for kind, n in sorted(counts.items())))
        for k, (old_line, line) in enumerate(zip(text.splitlines(), new.splitlines()), start=1):
            if old_line != line and REVIEW.search(line):
                review.append(f"{rel}:{k}: {line.strip()[:160]}")
        if args.write:
            path.write_text(new, encoding="utf-8")
    n = sum(total.values())
    verb = "rewrote" if args.write else "would rewrite"
    print(f"\n{verb} {n} references: " + ", ".join(f"{v} {k}" for k, v in sorted(total.items())))
    if review:
        print("\nreread these lines (the sentence may describe the old file, not docs/model.md):")
        print("\n".join(review))
    if left:
        print("\nplanning-issue references left for a person to rewrite:")
        print("\n".join(left))
    return 0


if __name__ == "__main__":
    sys.exit(main())
