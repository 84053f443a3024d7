"""The run catalogue: an index of run folders in SQLite (beside the runs) or PostgreSQL.

``Catalogue.open(url, runs_root)`` takes a path (an SQLite file, WAL mode) or a
``postgresql://`` URL; both go through the one schema (``twin.catalogue.schema``) and this
one code path (SQLAlchemy Core). The run folders stay the truth: ``reconcile`` indexes
folders the catalogue missed (a run that could not write to it) or that changed since, and
finds runs whose process died without a stop; ``rebuild`` recreates the whole index from the
folders. Every database failure is a :class:`CatalogueError`: one line, naming
``drumtwin runs rebuild`` where the file is corrupt or another program's.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Container, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from twin.catalogue import marks, schema
from twin.catalogue.summary import RunSummary, is_run_dir, summarise
from twin.errors import TwinError

CATALOGUE_ENV = "DRUMTWIN_CATALOGUE"
CATALOGUE_FILE = "catalogue.sqlite"
DEFAULT_RUNS_ROOT = "runs"


class CatalogueError(TwinError):
    """The catalogue cannot be used (corrupt, foreign, newer, unreachable): one line."""


@dataclass(frozen=True)
class RunFilter:
    """What ``runs list`` (and ``report``/``compare`` by filter) select; None: any."""

    rig: str | None = None
    mode: str | None = None
    tags: Sequence[tuple[str, str | None]] = ()  # (key, value or None for any value)
    since_s: float | None = None
    until_s: float | None = None
    mixed: bool | None = None
    rpm_lo: float | None = None
    rpm_hi: float | None = None
    ended: str | None = None
    golden: bool | None = None
    last: int | None = None


def resolve_url(url: str | None, runs_root: Path | str = DEFAULT_RUNS_ROOT) -> str:
    """The catalogue to use: ``url``, else ``$DRUMTWIN_CATALOGUE``, else
    ``<runs_root>/catalogue.sqlite``."""
    url = url or os.environ.get(CATALOGUE_ENV) or str(Path(runs_root) / CATALOGUE_FILE)
    return url


def hide_password(url: str) -> str:
    """A database URL with its password masked (for logs and metadata)."""
    try:
        return sa.make_url(url).render_as_string(hide_password=True)
    except Exception:  # not a URL at all: nothing to hide that we could find
        return url


def _engine_url(url: str) -> tuple[sa.URL, Path | None]:
    """An SQLAlchemy URL of a path or a database URL, and the SQLite file (None: a server)."""
    if "://" not in url:
        path = Path(url).expanduser().resolve()
        return sa.URL.create("sqlite", database=str(path)), path
    try:
        parsed = sa.make_url(url)
    except Exception as exc:  # SQLAlchemy's ArgumentError and ValueError alike
        raise CatalogueError(f"--catalogue {url!r} is not a path or a database URL ({exc})") from None
    if parsed.drivername in ("postgresql", "postgres"):
        parsed = parsed.set(drivername="postgresql+psycopg")
    if parsed.drivername.startswith("sqlite"):
        return parsed, Path(parsed.database).resolve() if parsed.database else None
    if not parsed.drivername.startswith("postgresql"):
        raise CatalogueError(f"--catalogue {parsed.drivername}://...: only an SQLite path or postgresql:// URL")
    return parsed, None


def check_url(url: str) -> None:
    """A one-line ``CatalogueError`` for a ``--catalogue`` no catalogue can be at, before anything
    runs: a scheme other than SQLite's or PostgreSQL's, a directory, a path under a regular file.
    (A file that is corrupt or a server that is down is found when it is used.)"""
    _sa_url, path = _engine_url(url)
    if path is None:
        return
    if path.is_dir():
        raise CatalogueError(f"--catalogue {path} is a directory: give the catalogue's file")
    parent = next((q for q in path.parents if q.exists()), None)
    if parent is not None and not parent.is_dir():
        raise CatalogueError(f"--catalogue {path}: {parent} is not a directory")


def runs_root_of(runs_dir: Path | None) -> Path:
    """The folder of the run folders: ``--runs-dir`` (which must be a folder: a typo is no new,
    empty catalogue), else ``runs``."""
    if runs_dir is None:
        return Path(DEFAULT_RUNS_ROOT)
    if not runs_dir.is_dir():
        raise CatalogueError(f"--runs-dir {runs_dir} is not a folder (the folder of the run folders)")
    return runs_dir


def open_for_runs(url: str | None, runs_dir: Path | None) -> Catalogue:
    """The catalogue a ``drumtwin runs`` command uses: ``url`` (checked), else the one beside the
    runs, whose folder must exist."""
    root = runs_root_of(runs_dir)
    if url is None and not os.environ.get(CATALOGUE_ENV) and not root.is_dir():
        raise CatalogueError(f"no folder of runs at {root} (the catalogue is beside the run folders): "
                             "give --runs-dir or --catalogue")
    resolved = resolve_url(url, root)
    check_url(resolved)
    return Catalogue(resolved, root)


def _unusable(where: str, exc: BaseException) -> CatalogueError:
    """The one line of a database failure: a full disk or a read-only place says so; anything
    else (corrupt, truncated, not a database) names ``runs rebuild``."""
    orig = getattr(exc, "orig", None) or exc
    first = (str(orig).strip().splitlines() or [type(orig).__name__])[0][:160]
    if any(w in first.lower() for w in ("disk is full", "readonly", "read-only", "unable to open", "locked")):
        return CatalogueError(f"cannot write the run catalogue {where}: {first}")
    return CatalogueError(f"the run catalogue {where} cannot be read ({first}): "
                          "run 'drumtwin runs rebuild' to recreate it from the run folders")


class Catalogue:
    """One catalogue connection (``with Catalogue.open(...) as cat``)."""

    def __init__(self, url: str, runs_root: Path | str = DEFAULT_RUNS_ROOT, *, create: bool = True) -> None:
        self.url = url
        self.runs_root = Path(runs_root)
        self._sa_url, self.sqlite_path = _engine_url(url)
        self.where = str(self.sqlite_path) if self.sqlite_path else self._sa_url.render_as_string(hide_password=True)
        self.engine = self._make_engine()
        self._ready(create)

    @classmethod
    def open(cls, url: str | None = None, runs_root: Path | str = DEFAULT_RUNS_ROOT, *,
             create: bool = True) -> Catalogue:
        return cls(resolve_url(url, runs_root), runs_root, create=create)

    # -- connection and schema -------------------------------------------------------------
    def _make_engine(self) -> sa.Engine:
        if self.sqlite_path is None:
            return sa.create_engine(self._sa_url, pool_pre_ping=True, connect_args={"connect_timeout": 5})
        check_url(str(self.sqlite_path))
        self.sqlite_path.parent.mkdir(parents=True, exist_ok=True)
        engine = sa.create_engine(self._sa_url, poolclass=sa.pool.NullPool, connect_args={"timeout": 15})
        sa.event.listen(engine, "connect", lambda dbapi_conn, _rec: schema.sqlite_pragmas(dbapi_conn))
        return engine

    def _ready(self, create: bool) -> None:
        """Check (and make or migrate) the schema; a foreign, corrupt or newer one refused."""
        try:
            with self.engine.begin() as conn:
                if self.sqlite_path is not None:
                    app_id = conn.exec_driver_sql("PRAGMA application_id").scalar()
                    tables = sa.inspect(conn).get_table_names()
                    if tables and app_id != schema.SQLITE_APPLICATION_ID:
                        raise CatalogueError(f"{self.where} is not a drumtwin catalogue (another program's "
                                             "database?): run 'drumtwin runs rebuild' to move it aside and recreate it")
                version = schema.read_version(conn)
                if version == -1:
                    raise CatalogueError(f"{self.where} holds another program's tables: "
                                         "run 'drumtwin runs rebuild' (it keeps the old file aside)")
                if version is not None and version > schema.SCHEMA_VERSION:
                    raise CatalogueError(f"the run catalogue {self.where} has schema version {version}, newer than "
                                         f"this drumtwin's {schema.SCHEMA_VERSION}: upgrade drumtwin to use it")
                if version is None and not create:
                    raise CatalogueError(f"no run catalogue at {self.where}: run 'drumtwin runs rebuild'")
                if version is None or version < schema.SCHEMA_VERSION:
                    schema.migrate(conn, version)
                    if self.sqlite_path is not None:
                        conn.exec_driver_sql(f"PRAGMA application_id = {schema.SQLITE_APPLICATION_ID}")
        except CatalogueError:
            raise
        except sa.exc.OperationalError as exc:
            if self.sqlite_path is None:
                raise CatalogueError(f"cannot reach the run catalogue {self.where}: "
                                     f"{str(exc.orig).strip().splitlines()[0][:160]}") from None
            raise _unusable(self.where, exc) from None
        except sa.exc.DatabaseError as exc:
            raise _unusable(self.where, exc) from None

    @contextlib.contextmanager
    def _begin(self) -> Iterator[sa.Connection]:
        """A transaction whose database errors are one-line :class:`CatalogueError`s."""
        try:
            with self.engine.begin() as conn:
                yield conn
        except sa.exc.DBAPIError as exc:
            raise _unusable(self.where, exc) from None

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Catalogue:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writing ---------------------------------------------------------------------------------
    def upsert(self, summaries: Iterable[RunSummary]) -> int:
        """Insert or replace the rows of ``summaries`` (and their tags) in one transaction."""
        rows = list(summaries)
        if not rows:
            return 0
        try:
            for attempt in range(3):  # a second writer inserted one of these ids between our delete and insert
                try:
                    self._replace(rows)
                    break
                except sa.exc.IntegrityError:
                    if attempt == 2:
                        raise
        except sa.exc.DBAPIError as exc:
            raise _unusable(self.where, exc) from None
        return len(rows)

    def _replace(self, rows: Sequence[RunSummary]) -> None:
        with self.engine.begin() as conn:
            ids = [s.id for s in rows]
            for chunk in _chunks(ids, 500):
                conn.execute(schema.tags.delete().where(schema.tags.c.run_id.in_(chunk)))
                conn.execute(schema.runs.delete().where(schema.runs.c.id.in_(chunk)))
            paths = [s.path for s in rows]
            for chunk in _chunks(paths, 500):  # a folder re-indexed under a new uid
                conn.execute(schema.runs.delete().where(schema.runs.c.path.in_(chunk)))
            conn.execute(schema.runs.insert(), [s.row() for s in rows])
            tag_rows = [{"run_id": s.id, "key": k, "value": v} for s in rows for k, v in s.tags.items()]
            if tag_rows:
                conn.execute(schema.tags.insert(), tag_rows)

    def index_folder(self, directory: Path | str) -> RunSummary | None:
        """Index (or re-index) one run folder with its annotations; the rig's golden mark is
        settled among the rig's runs."""
        s = summarise(directory)
        if s is None:
            return None
        ann = marks.read(directory)
        s = replace(s, tags=ann["tags"], note=ann["note"])
        self.upsert([s])
        if ann["golden_s"] is not None:
            self._settle_golden(s.rig, s.id, ann["golden_s"])
        return self.get(s.id)

    def _settle_golden(self, rig: str, run: str, marked_s: float) -> None:
        """``run`` is its rig's golden batch unless another run was marked later."""
        with self._begin() as conn:
            rows = conn.execute(sa.select(schema.runs.c.id, schema.runs.c.path)
                                .where(schema.runs.c.rig == rig, schema.runs.c.golden.is_(True))).all()
            for other in rows:
                other_s = marks.read(other.path)["golden_s"]
                if other.id != run and other_s is not None and other_s > marked_s:
                    return
            conn.execute(schema.runs.update().where(schema.runs.c.rig == rig).values(golden=False))
            conn.execute(schema.runs.update().where(schema.runs.c.id == run).values(golden=True))

    def tag(self, run: str, key: str, value: str) -> RunSummary:
        s = self.get(run)
        marks.append(s.path, tag={key: value})
        return self._reindexed(s)

    def note(self, run: str, text: str) -> RunSummary:
        s = self.get(run)
        marks.append(s.path, note=text)
        return self._reindexed(s)

    def golden(self, run: str) -> RunSummary:
        s = self.get(run)
        marks.append(s.path, golden=True)
        return self._reindexed(s)

    def _reindexed(self, s: RunSummary) -> RunSummary:
        out = self.index_folder(s.path)
        if out is None:
            raise CatalogueError(f"run {s.id}: its folder {s.path} holds no run files any more")
        return out

    # -- reading ---------------------------------------------------------------------------------
    def list(self, f: RunFilter = RunFilter()) -> list[RunSummary]:
        """Runs matching ``f``, newest first."""
        r = schema.runs.c
        q = sa.select(schema.runs).order_by(r.started_s.desc())
        conds = [
            c for c in (
                r.rig == f.rig if f.rig is not None else None,
                r.mode == f.mode if f.mode is not None else None,
                r.started_s >= f.since_s if f.since_s is not None else None,
                r.started_s < f.until_s if f.until_s is not None else None,
                r.mixed.is_(f.mixed) if f.mixed is not None else None,
                r.rpm_max >= f.rpm_lo if f.rpm_lo is not None else None,
                r.rpm_min <= f.rpm_hi if f.rpm_hi is not None else None,
                r.ended == f.ended if f.ended is not None else None,
                r.golden.is_(f.golden) if f.golden is not None else None,
            ) if c is not None
        ]
        for key, value in f.tags:
            sel = sa.select(schema.tags.c.run_id).where(schema.tags.c.key == key)
            if value is not None:
                sel = sel.where(schema.tags.c.value == value)
            conds.append(r.id.in_(sel))
        if conds:
            q = q.where(*conds)
        if f.last is not None:
            q = q.limit(f.last)
        with self._begin() as conn:
            rows = conn.execute(q).mappings().all()
            ids = [row["id"] for row in rows]
            tags: dict[str, dict[str, str]] = {}
            for chunk in _chunks(ids, 500):
                for t in conn.execute(sa.select(schema.tags).where(schema.tags.c.run_id.in_(chunk))):
                    tags.setdefault(t.run_id, {})[t.key] = t.value
        return [RunSummary(**dict(row), tags=tags.get(row["id"], {})) for row in rows]

    def get(self, run: str) -> RunSummary:
        """One run by its id, a unique prefix of it, its folder's path or its folder's name."""
        if not run.strip():
            raise CatalogueError("give a run: its id (or a prefix of it) or its folder ('drumtwin runs list')")
        r = schema.runs.c
        which = [r.id == run, r.id.startswith(run, autoescape=True), r.path.endswith(os.sep + run, autoescape=True)]
        if os.sep in run or Path(run).is_dir():
            which.append(r.path == str(Path(run).resolve()))
        with self._begin() as conn:
            rows = conn.execute(sa.select(r.id).where(sa.or_(*which)).limit(3)).scalars().all()
        exact = [x for x in rows if x == run]
        if exact or len(rows) == 1:
            return self._one((exact or rows)[0])
        if not rows:
            raise CatalogueError(f"no run {run!r} in the catalogue {self.where} ('drumtwin runs list' shows them)")
        raise CatalogueError(f"run {run!r} is ambiguous: {', '.join(rows)}, ... (give more of its id)")

    def _one(self, run: str) -> RunSummary:
        with self._begin() as conn:
            row = conn.execute(sa.select(schema.runs).where(schema.runs.c.id == run)).mappings().one()
            tags = {t.key: t.value for t in conn.execute(sa.select(schema.tags).where(schema.tags.c.run_id == run))}
        return RunSummary(**dict(row), tags=tags)

    def golden_of(self, rig: str) -> RunSummary | None:
        found = self.list(RunFilter(rig=rig, golden=True, last=1))
        return found[0] if found else None

    def count(self) -> int:
        with self._begin() as conn:
            return int(conn.execute(sa.select(sa.func.count()).select_from(schema.runs)).scalar_one())

    # -- keeping the index true to the folders ---------------------------------------------------
    def reconcile(self, roots: Sequence[Path | str] = ()) -> int:
        """Index the run folders under ``roots`` (default: the runs root) that the catalogue does
        not hold (a run that could not reach it), and re-read those it holds as running (a run
        that ended without telling it, or was killed). One directory listing and no per-file
        look at finished runs: it stays quick at many thousands of runs. Returns how many rows
        changed."""
        with self._begin() as conn:
            known = {row.path: row.ended for row in
                     conn.execute(sa.select(schema.runs.c.path, schema.runs.c.ended))}
        todo = [d for d in _run_folders(roots or [self.runs_root], known) if known.get(str(d)) in (None, "running")]
        changed = 0
        for d in todo:
            s = summarise(d)
            if s is not None and (str(d) not in known or s.ended != "running"):
                self.index_folder(d)
                changed += 1
        return changed

    def rebuild(self, roots: Sequence[Path | str] = (), progress: Callable[[int], None] | None = None) -> int:
        """Recreate the index from the run folders under ``roots`` (in one transaction)."""
        summaries: list[RunSummary] = []
        golden: dict[str, tuple[float, str]] = {}
        for i, d in enumerate(_run_folders(roots or [self.runs_root]), 1):
            s = summarise(d)
            if s is not None:
                ann = marks.read(d)
                s = replace(s, tags=ann["tags"], note=ann["note"])
                if ann["golden_s"] is not None and ann["golden_s"] > golden.get(s.rig, (-1.0, ""))[0]:
                    golden[s.rig] = (ann["golden_s"], s.id)
                summaries.append(s)
            if progress is not None and i % 500 == 0:
                progress(i)
        marked = {run for _t, run in golden.values()}
        summaries = [replace(s, golden=s.id in marked) for s in summaries]
        seen: set[str] = set()
        unique = [s for s in summaries if not (s.id in seen or seen.add(s.id))]  # type: ignore[func-returns-value]
        with self._begin() as conn:
            conn.execute(schema.tags.delete())
            conn.execute(schema.runs.delete())
            for chunk in _chunks(unique, 2000):
                conn.execute(schema.runs.insert(), [s.row() for s in chunk])
                tag_rows = [{"run_id": s.id, "key": k, "value": v} for s in chunk for k, v in s.tags.items()]
                if tag_rows:
                    conn.execute(schema.tags.insert(), tag_rows)
        return len(unique)


def rebuild(url: str | None, runs_root: Path | str = DEFAULT_RUNS_ROOT, roots: Sequence[Path | str] = (),
            progress: Callable[[int], None] | None = None) -> tuple[int, str | None]:
    """``drumtwin runs rebuild``: the index recreated from the run folders. An SQLite file that
    is corrupt or another program's is moved aside first (its new name is returned), never
    deleted; the new index is built in a temporary file and put in place atomically. A
    catalogue of a newer schema is refused (upgrade drumtwin)."""
    resolved = resolve_url(url, runs_root)
    check_url(resolved)  # never a directory or a path under a file: only a regular file is kept aside
    _sa_url, path = _engine_url(resolved)
    if path is None:
        with Catalogue(resolved, runs_root) as cat:
            return cat.rebuild(roots, progress), None
    moved: str | None = None
    if path.is_file():
        try:
            Catalogue(resolved, runs_root, create=False).close()
        except CatalogueError as exc:
            if "newer than" in str(exc):
                raise
            aside = path.with_name(f"{path.name}.unreadable-{int(time.time())}")
            os.replace(path, aside)
            moved = str(aside)
    tmp = path.with_name(f".{path.name}.rebuild-{os.getpid()}")
    for stale in (tmp, *_sidecars(tmp)):
        stale.unlink(missing_ok=True)
    try:
        with Catalogue(str(tmp), runs_root) as cat:
            n = cat.rebuild(roots, progress)
            with cat.engine.connect() as conn:  # fold the WAL into the file before it moves
                conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")
        for side in _sidecars(path):
            side.unlink(missing_ok=True)
        os.replace(tmp, path)
    finally:
        for stale in (tmp, *_sidecars(tmp)):
            stale.unlink(missing_ok=True)
    return n, moved


def _sidecars(path: Path) -> tuple[Path, Path]:
    """An SQLite file's write-ahead log and shared-memory index."""
    return path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")


def _chunks(items: Sequence[Any], n: int) -> Iterator[Sequence[Any]]:
    for i in range(0, len(items), n):
        yield items[i:i + n]


def _run_folders(roots: Iterable[Path | str], known: Container[str] = ()) -> Iterator[Path]:
    """Run folders: each root that is one, else its direct sub-folders that are (sorted); a
    folder in ``known`` is taken as a run folder without looking inside."""
    for root in roots:
        r = Path(root).resolve()
        if not r.is_dir():
            continue
        if str(r) in known or is_run_dir(r):
            yield r
            continue
        with os.scandir(r) as it:
            subs = sorted(e.path for e in it if e.is_dir(follow_symlinks=False))
        for p in subs:
            if p in known or is_run_dir(Path(p)):
                yield Path(p)
