"""``--dist loadgroup`` groups (tests/xdist_groups.py): the whole-loop tests of group "live" run on
one worker, one after another, and a session fixture (``group_fixture``) used inside a group runs once."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

CONFTEST = '''
import os
import pytest

def pytest_configure(config):
    config.pluginmanager.import_plugin("tests.xdist_groups")

@pytest.fixture(scope="session")
def group_fixture():
    with open(os.environ["RUNS_FILE"], "a") as f:
        f.write(os.environ.get("PYTEST_XDIST_WORKER", "-") + "\\n")
    return 1
'''

# a module-level group, a per-test group, a group on one parameter (as the bad-input sweep's
# bench dashboard base), each beside ungrouped tests the load scheduler spreads over both workers
TEST_A = '''
import pytest
pytestmark = pytest.mark.xdist_group("live")
@pytest.mark.parametrize("i", range(3))
def test_module_group(i, group_fixture):
    assert group_fixture == 1
'''
TEST_B = '''
import pytest
LIVE = pytest.mark.xdist_group("live")
@pytest.mark.parametrize("i", range(6))
def test_free(i):
    pass
@LIVE
def test_marked(group_fixture):
    assert group_fixture == 1
@pytest.mark.parametrize("k", [pytest.param(k, marks=LIVE) if k == "b" else k for k in "abcdef"])
def test_param(k, request):
    if k == "b":
        assert request.getfixturevalue("group_fixture") == 1
'''

# an ungrouped module whose tests share a module-scoped fixture of their own (a rendered rig, a commissioning)
TEST_C = '''
import os
import pytest
@pytest.fixture(scope="module")
def rig():
    with open(os.environ["RUNS_FILE"] + ".rig", "a") as f:
        f.write(os.environ.get("PYTEST_XDIST_WORKER", "-") + "\\n")
    return 2
@pytest.mark.parametrize("i", range(6))
def test_rig(i, rig):
    assert rig == 2
'''


def test_loadgroup_puts_a_group_on_one_worker_and_its_session_fixture_runs_once(tmp_path: Path) -> None:
    (tmp_path / "conftest.py").write_text(CONFTEST)
    (tmp_path / "test_a.py").write_text(TEST_A)
    (tmp_path / "test_b.py").write_text(TEST_B)
    (tmp_path / "test_c.py").write_text(TEST_C)
    runs = tmp_path / "runs.txt"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "COV_"))}
    env.update(PYTHONPATH=str(REPO), RUNS_FILE=str(runs))
    p = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadgroup", "-v",
                        "-p", "no:cacheprovider", "-p", "no:randomly", "--rootdir", str(tmp_path), str(tmp_path)],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-2000:]
    ran = re.findall(r"\[(gw\d)\] .*?PASSED (\S+)", p.stdout)
    live = [f"test_a.py::test_module_group[{i}]" for i in range(3)] + ["test_b.py::test_marked",
                                                                     "test_b.py::test_param[b]"]
    grouped = {nodeid: gw for gw, nodeid in ran if nodeid.split("@")[0] in live}
    assert len(ran) == 3 + 6 + 1 + 6 + 6, p.stdout[-3000:]
    assert len(grouped) == 5 and all(n.endswith("@live") for n in grouped), grouped
    assert len(set(grouped.values())) == 1, grouped  # one worker for the whole group
    assert len({gw for gw, _ in ran}) == 2, ran  # the free tests did go to both workers
    assert runs.read_text().split() == [next(iter(grouped.values()))]  # the session fixture once
    rig = {gw for gw, nodeid in ran if nodeid.startswith("test_c.py::")}
    assert len(rig) == 1 and len(Path(f"{runs}.rig").read_text().split()) == 1, ran  # its module fixture once


def test_a_test_in_two_groups_is_refused_by_name() -> None:
    """xdist puts a test marked with groups "commission" and "live" in a third group, "commission_live",
    on any worker: the must-show commissioning that group "commission" shares ran twice, and a loop ran
    beside the "live" chain. Such a test fails at its set-up (before its fixtures), by name."""
    import pytest

    from tests.xdist_groups import one_group

    class Item:
        nodeid = "tests/x.py::test_y"

        def __init__(self, *names: str) -> None:
            self.marks = [pytest.mark.xdist_group(n).mark for n in names]

        def iter_markers(self, name: str):
            return iter(m for m in self.marks if m.name == name)

    for fine in (Item("live"), Item("live", "live"), Item()):  # one group, twice (module and test), none
        one_group(fine)  # type: ignore[arg-type]
    with pytest.raises(pytest.fail.Exception, match=r"tests/x.py::test_y: in xdist groups \['commission', 'live'\]"):
        one_group(Item("commission", "live"))  # type: ignore[arg-type]
