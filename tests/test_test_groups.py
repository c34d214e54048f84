"""The CI's test processes keep each ``xdist_group`` in one process (`make test`: pytest-xdist ``--dist
loadgroup``): the tests of one costly build (the GPU build check) or kernel family (tier 2's) rely on it, so that a
cold kernel cache compiles them once. pytest 9 with pytest-xdist 3.8 dropped the groups without a word
(pyproject.toml pins pytest below 9)."""

import subprocess
import sys

PROBE = '''
import os
import pytest

pytestmark = pytest.mark.xdist_group("probe")


@pytest.mark.parametrize("i", range(4))
def test_probe(i, request):
    with open(f"seen-{i}.txt", "w") as out:
        out.write(os.environ["PYTEST_XDIST_WORKER"] + " " + request.node.nodeid)
'''


def test_a_group_runs_in_one_of_two_test_processes(tmp_path):
    """Four tests of one group run by two test processes under ``--dist loadgroup`` (a pytest of their own in a
    scratch folder, about 3 s): every node id carries the group (how pytest-xdist's scheduler finds it) and one
    process ran all four. Seen with pytest 9.2 and pytest-xdist 3.8: the ids without the group, the tests dealt
    to both processes; the mark removed does the same here (planted, fails)."""
    (tmp_path / "test_probe.py").write_text(PROBE)
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-p",
                          "no:cacheprovider", "test_probe.py"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    seen = [(tmp_path / f"seen-{i}.txt").read_text().split(" ", 1) for i in range(4)]
    assert all(nodeid.endswith("@probe") for _, nodeid in seen), seen
    assert len({worker for worker, _ in seen}) == 1, seen
