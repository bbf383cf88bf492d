"""package.xml declares every import of the package, its launch files and its tests."""

import ast
from pathlib import Path
import sys
import xml.etree.ElementTree as ET

REPO = Path(__file__).resolve().parent.parent
# top-level import -> the package.xml key that provides it (ROS packages: their own name)
KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'matplotlib': 'python3-matplotlib',
    'yaml': 'python3-yaml', 'lz4': 'python3-lz4', 'zstandard': 'python3-zstandard',
    'mcap': 'python3-mcap-pip', 'rosbags': 'python3-rosbags-pip',
    'pytest': 'python3-pytest', 'hypothesis': 'python3-hypothesis',
    'mcap_ros2': 'python3-mcap-ros2-support-pip',
    'pyvisa': 'python3-pyvisa-pip', 'pyvisa_sim': 'python3-pyvisa-sim-pip',
    'dask': 'python3-dask-pip', 'distributed': 'python3-distributed-pip', 'tqdm': 'python3-tqdm',
}
RUN = ('exec_depend', 'depend')
TEST = RUN + ('test_depend',)


def declared(kinds):
    root = ET.parse(REPO / 'package.xml').getroot()
    return {e.text.strip() for kind in kinds for e in root.iter(kind)}


def top_level_imports(paths):
    found = {}
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            for name in names:
                top = name.split('.')[0]
                local = ((REPO / 'test' / f'{top}.py').is_file()
                         or (REPO / 'test' / top / '__init__.py').is_file())
                if top not in sys.stdlib_module_names and top != 'tskf_ros' and not local:
                    found.setdefault(top, path.name)
    return found


def missing(imports, kinds):
    have = declared(kinds)
    return {top: where for top, where in imports.items() if KEYS.get(top, top) not in have}


def test_every_runtime_import_is_an_exec_depend():
    code = sorted((REPO / 'tskf_ros').rglob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
    imports = top_level_imports(code)
    assert {'rclpy', 'rcl_interfaces', 'numpy', 'launch_ros', 'mcap'} <= set(imports)
    assert missing(imports, RUN) == {}


def test_every_test_import_is_declared():
    imports = top_level_imports(sorted((REPO / 'test').rglob('*.py')))
    assert missing(imports, TEST) == {}


def test_the_check_catches_an_undeclared_import(tmp_path):
    code = tmp_path / 'x.py'
    code.write_text('import pandas\nfrom nav_msgs.msg import Odometry\nimport json\n')
    assert set(missing(top_level_imports([code]), RUN)) == {'pandas', 'nav_msgs'}
