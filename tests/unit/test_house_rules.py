"""House rules that keep the services independent (DESIGN.md section 2)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def imported_modules(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def cross_imports(root: Path) -> list[str]:
    """Every `services.Y` import found under services/X with X != Y."""
    problems = []
    services = root / "services"
    for service_dir in sorted(p for p in services.iterdir() if p.is_dir()):
        for path in service_dir.rglob("*.py"):
            for module in imported_modules(path):
                parts = module.split(".")
                if parts[0] == "services" and len(parts) > 1 and parts[1] != service_dir.name:
                    problems.append(f"{path.relative_to(root)} imports {module}")
    return problems


def test_no_service_imports_another_service() -> None:
    assert cross_imports(ROOT) == []


def test_common_imports_no_service() -> None:
    offenders = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path in (ROOT / "common").rglob("*.py")
        for module in imported_modules(path)
        if module.split(".")[0] == "services"
    ]
    assert offenders == []


def test_the_check_catches_a_cross_import(tmp_path: Path) -> None:
    (tmp_path / "services" / "planner").mkdir(parents=True)
    (tmp_path / "services" / "controller").mkdir(parents=True)
    (tmp_path / "services" / "planner" / "ok.py").write_text("from services.planner import x\n")
    (tmp_path / "services" / "controller" / "bad.py").write_text(
        "def f():\n    import services.planner.rules\n"
    )
    assert cross_imports(tmp_path) == ["services/controller/bad.py imports services.planner.rules"]
