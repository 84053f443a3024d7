"""The run catalogue on a real PostgreSQL server (issue 40): the same schema and code path as
SQLite, two writers at once, a newer schema refused."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import sqlalchemy as sa

from tests.catalogue_runs import RunSpec, make_run
from tests.cli import assert_one_line_error, cli
from tests.pg import fresh_database, postgres_url  # noqa: F401 -- the session's server
from twin.catalogue import schema
from twin.catalogue.store import Catalogue


def _listed(url: str, runs: Path, *args: object) -> list[dict]:
    r = cli("runs", "list", "--catalogue", url, "--runs-dir", runs, "--json", *args)
    assert r.code == 0, r.err
    return json.loads(r.out)


def test_list_tag_golden_and_rebuild_on_postgres(tmp_path: Path, postgres_url: str) -> None:  # noqa: F811
    url = fresh_database(postgres_url, "cat_basic")
    runs = tmp_path / "runs"
    make_run(runs / "a", RunSpec(rig="pmma", mixing_time_s=20.0))
    make_run(runs / "b", RunSpec(rig="pmma", mixing_time_s=None))
    rows = {Path(r["path"]).name: r for r in _listed(url, runs)}
    assert rows["a"]["mixed"] is True and rows["b"]["mixed"] is False
    assert cli("runs", "tag", rows["a"]["id"], "lot=7", "--catalogue", url, "--runs-dir", runs).code == 0
    assert cli("runs", "golden", rows["a"]["id"], "--catalogue", url, "--runs-dir", runs).code == 0
    assert cli("runs", "rebuild", "--catalogue", url, "--runs-dir", runs).code == 0
    [a] = _listed(url, runs, "--tag", "lot=7")
    assert a["golden"] is True and Path(a["path"]).name == "a"
    assert not (runs / "catalogue.sqlite").exists()  # the server holds it


def test_two_writers_at_once_on_one_server(tmp_path: Path, postgres_url: str) -> None:  # noqa: F811
    url = fresh_database(postgres_url, "cat_two")
    runs = tmp_path / "runs"
    names = [f"r{i:02d}" for i in range(40)]
    for n in names:
        make_run(runs / n)
    Catalogue.open(url, runs).close()
    code = ("import sys; from pathlib import Path; from twin.catalogue.store import Catalogue;"
            "cat = Catalogue.open(sys.argv[1], sys.argv[2]);"
            "[cat.index_folder(Path(sys.argv[2]) / n) for n in sys.argv[3:]]")
    procs = [subprocess.Popen([sys.executable, "-c", code, url, str(runs), *part], stderr=subprocess.PIPE,
                              cwd=Path(__file__).parents[2]) for part in (names[0::2], names[1::2])]
    for p in procs:
        _out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err.decode()[-2000:]
    with Catalogue.open(url, runs) as cat:
        assert cat.count() == 40


def test_a_newer_schema_on_the_server_is_refused(tmp_path: Path, postgres_url: str) -> None:  # noqa: F811
    url = fresh_database(postgres_url, "cat_newer")
    Catalogue.open(url, tmp_path).close()
    engine = sa.create_engine(url.replace("postgresql://", "postgresql+psycopg://"))
    with engine.begin() as conn:
        conn.execute(schema.schema_info.update().values(version=schema.SCHEMA_VERSION + 3))
    engine.dispose()
    assert_one_line_error(cli("runs", "list", "--catalogue", url, "--runs-dir", tmp_path), "newer", "upgrade")


def test_an_unreachable_server_is_one_line(tmp_path: Path) -> None:
    assert_one_line_error(cli("runs", "list", "--catalogue", "postgresql://nobody@127.0.0.1:1/x",
                              "--runs-dir", tmp_path), "cannot reach the run catalogue")
