"""The import contracts of issue 15: imports go one way (node, headless, demo → rerun_replay
→ msg_adapters, rerun_logger → core), the core is pure (no ROS, no Rerun, nothing of the
package outside the core) and no module takes part in an import cycle.

Two checks read the package: import-linter's contracts in setup.cfg (`layers`, `forbidden`,
`acyclic_siblings`) and, for the cycles `acyclic_siblings` cannot see (a package's
``__init__`` and one of its own submodules importing each other), a search of grimp's
module graph (`python test/test_layers.py paper_sim_ros`). Both run on a copy of the package
laid out as installed: msg_adapters/ lives at the top of the repository and installs as
``paper_sim_ros.msg_adapters`` (setup.py's package_dir), which grimp does not find through an
editable install. On such a copy a test also adds a forbidden import and sees the checks fail.
"""
import importlib.util
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / 'setup.cfg'
PACKAGE = 'paper_sim_ros'
LINT_IMPORTS = Path(sys.executable).parent / 'lint-imports'
INSTALLED_ELSEWHERE = ('msg_adapters',)
"""Subpackages that setup.py's package_dir installs from outside paper_sim_ros/."""


def install_copy(destination: Path) -> Path:
    """Copy the package as Python imports it to destination/paper_sim_ros, the subpackages
    that live elsewhere in their installed place; return destination."""
    ignore = shutil.ignore_patterns('__pycache__')
    package = Path(importlib.util.find_spec(PACKAGE).submodule_search_locations[0])
    shutil.copytree(package, destination / PACKAGE, ignore=ignore)
    for name in INSTALLED_ELSEWHERE:
        spec = importlib.util.find_spec(f'{PACKAGE}.{name}')
        if not (destination / PACKAGE / name).exists():
            shutil.copytree(Path(spec.submodule_search_locations[0]),
                            destination / PACKAGE / name, ignore=ignore)
    return destination


def check_imports(root: Path) -> tuple[bool, str]:
    """Run the contracts and the cycle search on the package copied to root: whether both
    pass, and what they said."""
    if not LINT_IMPORTS.exists():
        pytest.fail(f'{LINT_IMPORTS} not found: pip install import-linter')
    env = {**os.environ, 'PYTHONPATH': str(root)}
    runs = [subprocess.run(command, cwd=root, env=env, capture_output=True, text=True,
                           timeout=120)
            for command in ([str(LINT_IMPORTS), '--config', str(CONFIG), '--no-cache'],
                            [sys.executable, __file__, PACKAGE])]
    output = '\n'.join(run.stdout + run.stderr for run in runs)
    return all(run.returncode == 0 for run in runs), output


def append_import(root: Path, file: str, statement: str) -> int:
    """Append statement to the copied package's file; return its line number."""
    path = root / PACKAGE / file
    text = path.read_text()
    if not text.endswith('\n'):
        text += '\n'
    path.write_text(f'{text}{statement}  # deliberate, by test_layers.py\n')
    return text.count('\n') + 1


@pytest.fixture(scope='module')
def installed(tmp_path_factory) -> Path:
    return install_copy(tmp_path_factory.mktemp('installed'))


def test_imports_keep_the_layers_the_pure_core_and_no_cycles(installed):
    assert (installed / PACKAGE / 'msg_adapters' / 'markers.py').exists()
    kept, output = check_imports(installed)
    assert kept, f'import contracts broken (setup.cfg [importlinter]):\n{output}'


@pytest.mark.parametrize('file, statement, expected', [
    ('core/sheet.py', 'from paper_sim_ros import node',
     ['paper_sim_ros.core is not allowed to import paper_sim_ros.node',
      'paper_sim_ros.core.sheet -> paper_sim_ros.node (l.{line})',
      'No cycles are allowed in paper_sim_ros.']),
    ('core/sheet.py', 'import rclpy',
     ['paper_sim_ros.core is not allowed to import rclpy',
      'paper_sim_ros.core.sheet -> rclpy (l.{line})']),
    ('msg_adapters/markers.py', 'from paper_sim_ros.rerun_replay import replay_command',
     ['paper_sim_ros.msg_adapters is not allowed to import paper_sim_ros.rerun_replay',
      'paper_sim_ros.msg_adapters.markers -> paper_sim_ros.rerun_replay (l.{line})']),
    ('core/topology.py', 'from .sheet import Sheet',
     ['No cycles are allowed in paper_sim_ros.core.',
      'paper_sim_ros.core.topology -> paper_sim_ros.core.sheet (l.{line})']),
    # a cycle through the core's __init__, which only the grimp search sees
    ('core/sheet.py', 'from paper_sim_ros.core import Simulator',
     ['paper_sim_ros.core.sheet -> paper_sim_ros.core (l.{line})']),
], ids=['core imports the node', 'core imports rclpy', 'adapter imports replay',
        'cycle in the core', 'cycle through core/__init__'])
def test_a_forbidden_import_breaks_the_check_and_is_named(tmp_path, file, statement, expected):
    root = install_copy(tmp_path)
    line = append_import(root, file, statement)
    kept, output = check_imports(root)
    assert not kept, f'{statement!r} in {file} went unnoticed:\n{output}'
    for text in expected:
        assert text.format(line=line) in output, f'{text.format(line=line)!r} not in:\n{output}'


# --------------------------------------------------------------- the module cycle search
def module_cycles(package: str) -> list[str]:
    """Every group of modules of package that import each other (directly or not), each
    with one cycle through it, link by link with line numbers."""
    import grimp

    graph = grimp.build_graph(package, cache_dir=None)
    internal = {m for m in graph.modules if m == package or m.startswith(f'{package}.')}
    reports, seen = [], set()
    for module in sorted(internal):
        if module in seen:
            continue
        group = (graph.find_downstream_modules(module)
                 & graph.find_upstream_modules(module) & internal)
        if not group and module not in graph.find_modules_directly_imported_by(module):
            continue
        group |= {module}
        seen |= group
        first = min(graph.find_modules_directly_imported_by(module) & group)
        chain = graph.find_shortest_chain(importer=first, imported=module)
        cycle = (module,) + (chain or (module,))  # no chain: the module imports itself
        lines = [f'Import cycle among {", ".join(sorted(group))}:']
        for importer, imported in zip(cycle, cycle[1:]):
            numbers = sorted({d['line_number']
                              for d in graph.get_import_details(importer=importer,
                                                                imported=imported)})
            lines.append(f'- {importer} -> {imported} '
                         f'({", ".join(f"l.{n}" for n in numbers)})')
        reports.append('\n'.join(lines))
    return reports


if __name__ == '__main__':
    found = module_cycles(sys.argv[1])
    print('\n\n'.join(found) if found
          else f'No import cycles between the modules of {sys.argv[1]}.')
    sys.exit(1 if found else 0)
