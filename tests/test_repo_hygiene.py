"""The repository speaks for itself: no tracked file points outside it or recounts how it was made.

Rules, applied to every tracked text file (``git ls-files``; binary files are skipped):

1. **No paths outside the repository.** A relative path that climbs above the repository root from the
   file's folder (one ``..`` step too many) and absolute paths of a particular machine (below the roots
   ``work``, ``home``, ``root``, ``Users``, ``mnt``, or a Windows user folder) are errors. Generated
   records (training results, field-log metadata) must store repository-relative paths.
2. **One model specification, docs/model.md.** Every mention of the specification's file name must
   name that file: as the repository-relative path docs/model.md (prose and code: "docs/model.md §3")
   or as a relative path or link that resolves to it from the mentioning file. The upper-case spelling
   is never allowed (it was the name of a specification kept outside the repository).
3. **Relative Markdown links resolve.** ``[text](target)`` in a tracked ``.md`` file, with a target that is
   not a URL or an anchor, must name a tracked file or folder.
4. **No process history.** The word issue(s) followed by a number (optionally ``#``) or by a quoted
   title recounts how the software was planned, not what it is. The word alone ("a known issue") is
   allowed.

The examples at the end of this file are built from pieces so that the file passes its own scan.
``EXEMPT`` lists files that may break a rule and why.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

EXEMPT: dict[str, str] = {
    # Quotes the README's current text (old -> new) for the merge; delete it once the changes are applied.
    "docs/README-proposed-changes.md": "quotes text that is being replaced",
}

SPEC_NAME = "model" + ".md"  # built from pieces: this file passes its own scan
SPEC_PATH = "docs/" + SPEC_NAME

SKIP_SUFFIXES = {".png", ".jpg", ".jpeg", ".gif", ".pdf", ".zip", ".npz", ".npy", ".pkl", ".pt", ".gz"}

MACHINE_PATH = re.compile(r"(?<![\w.~-])(?:/(?:work|home|root|Users|mnt)/|[A-Za-z]:\\\\?Users\\)")
CLIMB = re.compile(r"(?<![\w.])((?:\.\./)+)([\w.-]*)")
SPEC_MENTION = re.compile(r"(?i)(?<![\w.-])((?:[\w.-]+/)*)(model\.md)\b")
MD_LINK = re.compile(r"\[[^\]\n]*\]\(([^)\s]+)\)")
PROCESS = re.compile(r"(?i)\bissues?\s+(?:#?\d+\b|\"[^\"\n]+\")")


def tracked_text_files() -> list[tuple[str, str]]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    files = []
    for rel in out.decode().split("\0"):
        path = ROOT / rel
        if not rel or rel in EXEMPT or path.suffix.lower() in SKIP_SUFFIXES or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue
        try:
            files.append((rel, data.decode("utf-8")))
        except UnicodeDecodeError:
            continue
    return files


FILES = tracked_text_files() if (ROOT / ".git").exists() else []
TRACKED = {rel for rel, _ in FILES}


def _tracked_path(rel: str) -> bool:
    """A tracked file, or a folder that holds one (any file type)."""
    out = subprocess.run(["git", "ls-files", "--", rel], cwd=ROOT, capture_output=True, text=True)
    return bool(out.stdout.strip())


def _findings(pattern_check) -> list[str]:
    found = []
    for rel, text in FILES:
        for k, line in enumerate(text.splitlines(), start=1):
            for msg in pattern_check(rel, line):
                found.append(f"{rel}:{k}: {msg}: {line.strip()[:140]}")
    return found


def _report(found: list[str], what: str) -> str:
    head = "\n".join(found[:60])
    more = f"\n... and {len(found) - 60} more" if len(found) > 60 else ""
    return f"{len(found)} {what}:\n{head}{more}"


def _resolves_outside(rel: str, climb: str) -> bool:
    depth = len(Path(rel).parent.parts)
    return climb.count("../") > depth


def check_outside_paths(rel: str, line: str):
    for m in MACHINE_PATH.finditer(line):
        yield f"absolute machine path {m.group(0)!r}"
    for m in CLIMB.finditer(line):
        if _resolves_outside(rel, m.group(1)):
            yield f"path outside the repository {m.group(0)!r}"


def check_spec_mentions(rel: str, line: str):
    for m in SPEC_MENTION.finditer(line):
        prefix, name = m.group(1), m.group(2)
        if name != SPEC_NAME:
            yield f"{prefix}{name!s}: the specification is {SPEC_PATH}"
            continue
        ref = prefix + name
        from_root = os.path.normpath(ref)
        from_here = os.path.normpath(os.path.join(os.path.dirname(rel), ref))
        if SPEC_PATH not in (from_root, from_here):
            yield f"{ref!r} does not name {SPEC_PATH}"


def check_md_links(rel: str, line: str):
    if not rel.endswith(".md"):
        return
    for m in MD_LINK.finditer(line):
        target = m.group(1).split("#", 1)[0]
        if not target or re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):
            continue  # anchor in the same file, or a URL (https:, mailto:)
        resolved = os.path.normpath(os.path.join(os.path.dirname(rel), target))
        if resolved.startswith(".."):
            yield f"link {m.group(1)!r} leaves the repository"
        elif not _tracked_path(resolved):
            yield f"link {m.group(1)!r} names no tracked file ({resolved})"


def check_process_history(rel: str, line: str):
    for m in PROCESS.finditer(line):
        yield f"process history {m.group(0)!r}"


def test_the_scan_sees_the_repository():
    assert "README.md" in TRACKED and "pyproject.toml" in TRACKED, "git ls-files found no project files"


def test_no_paths_outside_the_repository():
    found = _findings(check_outside_paths)
    assert not found, _report(found, "references to paths outside the repository")


def test_model_specification_is_docs_model_md():
    assert (ROOT / SPEC_PATH).is_file()
    found = _findings(check_spec_mentions)
    assert not found, _report(found, "references to a model specification other than docs/model.md")


def test_markdown_links_resolve():
    found = _findings(check_md_links)
    assert not found, _report(found, "broken relative links")


def test_no_process_history():
    found = _findings(check_process_history)
    assert not found, _report(found, "mentions of planning issues")


M = SPEC_NAME
UPPER = "MODEL" + ".md"
UP = ".." + "/"  # one step up
ISSUE = "issue"


@pytest.mark.parametrize("line, rel, bad", [
    (f"see docs/{M} §3", "trackenv/x.py", False),
    (f"[spec](docs/{M})", "README.md", False),
    (f"[spec]({UP}docs/{M})", "train/README.md", False),
    (f"[spec]({M}#4-normal-loads)", "docs/other.md", False),
    (f"the {UPPER} §8 ids", "trackenv/x.py", True),
    (f"[spec]({UP}shared/{UPPER})", "README.md", True),
    (f"spec in {UP}{M}", "README.md", True),
    (f"a port of {M}", "configs/field/x.yaml", True),
])
def test_spec_rule_examples(line, rel, bad):
    assert bool(list(check_spec_mentions(rel, line)) or list(check_outside_paths(rel, line))) == bad


@pytest.mark.parametrize("line, bad", [
    (f"({ISSUE} 4)", True), (f"{ISSUE.title()} 2 asked for", True), (f"{ISSUE}s #12 and #13", True),
    (f'{ISSUE} "Sim-to-real gap diagnosis"', True), (f"a known {ISSUE} with float32", False),
    (f"the next {ISSUE}", False), (f"t{ISSUE} 3", False),
])
def test_process_rule_examples(line, bad):
    assert bool(list(check_process_history("x.md", line))) == bad


@pytest.mark.parametrize("line, rel, bad", [
    ('"config_file": "/' + 'work/main/configs/train/ppo.yaml"', "train/r.json", True),
    ("/" + "home/user/data", "x.md", True), ("C:" + "\\Users\\me", "x.md", True),
    (f"[x]({UP}README.md)", "train/README.md", False), (f"[x]({UP}README.md)", "README.md", True),
    (f"{UP}{UP}configs", "configs/field/README.md", False), (f"{UP}{UP}configs", "configs/README.md", True),
    ("Path('/tmp/x')", "x.py", False), ("a .../b ellipsis", "x.md", False),
])
def test_outside_rule_examples(line, rel, bad):
    assert bool(list(check_outside_paths(rel, line))) == bad
