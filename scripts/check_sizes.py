"""List classes over 250 lines and functions over 60 lines in src/ (issue 13's size rule).

    python scripts/check_sizes.py [--max-class 250] [--max-function 60]
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path


def oversized(root: Path, max_class: int, max_function: int) -> list[str]:
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                n = node.end_lineno - node.lineno + 1
                limit = max_class if isinstance(node, ast.ClassDef) else max_function
                if n > limit:
                    found.append(f"{path}:{node.lineno} {node.name} {n} lines (limit {limit})")
    return found


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("root", nargs="?", default="src")
    p.add_argument("--max-class", type=int, default=250)
    p.add_argument("--max-function", type=int, default=60)
    a = p.parse_args()
    found = oversized(Path(a.root), a.max_class, a.max_function)
    print("\n".join(found) or "no class or function over the limits")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
