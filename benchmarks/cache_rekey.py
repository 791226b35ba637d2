"""Carry the zoo's cached runs over to today's mavtune source where it flies exactly as a committed one did.

quality.py keys each cached run by a hash of mavtune's source (`quality.engine_hash`), so that a run of another
engine is flown again. A change to docstrings, comments, layout or a setting's help text (pydantic's
`description=`) moves that hash but not one flight. This copies the runs cached under revision REV's hash to
today's, and refuses unless every module's syntax tree, docstrings and help texts set aside, equals REV's.

    python benchmarks/cache_rekey.py REV        # e.g. HEAD~1: the commit before a docstring edit
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from quality import CACHE, REPO, source_files, source_hash  # noqa: E402


def flight_tree(source: str) -> str:
    """A module's syntax tree without its docstrings and its pydantic help texts: what it flies."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(body, list) and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
        if isinstance(node, ast.keyword) and node.arg == "description":
            node.value = ast.Constant("")
    return ast.dump(tree)


def differences(old: dict[str, bytes], new: dict[str, bytes]) -> list[str]:
    """The modules (relative paths) whose flight trees differ between two sources, added or removed ones too."""
    return sorted(p for p in old.keys() | new.keys()
                  if p not in old or p not in new or flight_tree(old[p].decode()) != flight_tree(new[p].decode()))


def committed(rev: str) -> dict[str, bytes]:
    """mavtune's modules at git revision `rev`, by path relative to the repository."""
    names = subprocess.run(["git", "ls-tree", "-r", "--name-only", rev, "mavtune"], cwd=REPO, check=True,
                           capture_output=True).stdout.decode().split()
    return {n: subprocess.run(["git", "show", f"{rev}:{n}"], cwd=REPO, check=True, capture_output=True).stdout
            for n in names if n.endswith(".py")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the git revision whose cached runs today's source flies exactly as")
    args = ap.parse_args(argv)
    try:
        old = committed(args.rev)
    except subprocess.CalledProcessError as exc:
        ap.error(f"git cannot read mavtune at {args.rev!r}: {exc.stderr.decode().strip() or exc}")
    new = source_files()
    old_hash, new_hash = source_hash(old), source_hash(new)
    if moved := differences(old, new):
        print(f"refused: {', '.join(moved)} fly differently from {args.rev} (not only docstrings or help texts)",
              file=sys.stderr)
        return 1
    path = CACHE / "runs.jsonl"
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []
    have, copied = {r["key"] for r in rows}, []
    for row in rows:
        key = json.loads(row["key"])
        moved = json.dumps([*key[:-1], new_hash])
        if key[-1] == old_hash and moved not in have:
            copied.append({**row, "key": moved})
            have.add(moved)
    with path.open("a") as f:
        f.writelines(json.dumps(r) + "\n" for r in copied)
    print(f"copied {len(copied)} runs from engine {old_hash} ({args.rev}) to {new_hash}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
