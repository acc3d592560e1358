"""Every module the package imports at run time is declared (issue 15): a ROS package as an
``exec_depend`` of package.xml, anything else in setup.py's ``install_requires``, so that
neither a colcon user nor a pip user meets an ImportError (scipy once was missing)."""
import ast
import importlib.metadata
from pathlib import Path
import re
import sys
import xml.etree.ElementTree as ElementTree

REPO = Path(__file__).resolve().parents[1]
SOURCES = ('paper_sim_ros', 'msg_adapters')


def imported_modules() -> set[str]:
    """Top-level names of the modules the package's own files import, its own left out."""
    names = set()
    for folder in SOURCES:
        for path in (REPO / folder).rglob('*.py'):
            for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
                if isinstance(node, ast.Import):
                    names.update(alias.name.split('.')[0] for alias in node.names)
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - {'paper_sim_ros', '__future__'}


def requirement_name(requirement: str) -> str:
    return re.split(r'[\[<>=!~ ;]', requirement, maxsplit=1)[0].lower().replace('_', '-')


def install_requires() -> set[str]:
    """The distribution names of setup.py's ``install_requires``, normalised."""
    for node in ast.walk(ast.parse((REPO / 'setup.py').read_text(encoding='utf-8'))):
        if isinstance(node, ast.keyword) and node.arg == 'install_requires':
            return {requirement_name(value) for value in ast.literal_eval(node.value)}
    raise AssertionError('setup.py has no install_requires')


def test_every_imported_module_is_declared():
    distributions = importlib.metadata.packages_distributions()
    exec_depends = {element.text for element in
                    ElementTree.parse(REPO / 'package.xml').getroot().iter('exec_depend')}
    required = install_requires()
    undeclared = []
    for module in sorted(imported_modules()):
        names = [requirement_name(name) for name in distributions.get(module, [module])]
        if any(name.startswith('ros-') for name in names):  # a ROS package, by module name
            if module not in exec_depends:
                undeclared.append(f'{module}: no <exec_depend> in package.xml')
        elif not required & set(names):
            undeclared.append(f'{module} ({", ".join(names)}): not in setup.py install_requires')
    assert not undeclared, 'imported at run time but not declared:\n' + '\n'.join(undeclared)
