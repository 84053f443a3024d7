"""``--dist loadgroup`` that groups again on pytest 9.2 (a pytest plugin, loaded by tests/conftest.py).

pytest-xdist 3.8 tells its scheduler a test's ``xdist_group`` by appending ``@group`` to the
test's node id, and it does so by writing ``item._nodeid``. pytest 9.2 keeps the node id in
``item._id`` (a structured ``NodeId``), so that write changes nothing: every grouped test was
scheduled alone, the whole-loop tests of group "live" ran on both workers at once, and a
session fixture shared inside the group (``bench_dashboard_run``) ran once per worker
(pytest-dev/pytest-xdist#1386, fix proposed in #1388). Here, after xdist's own hook, a worker
gives a grouped test whose id still lacks the suffix the id xdist meant. Where xdist's write
works (older pytest, a fixed xdist) the suffix is already there and this does nothing.
"""

from __future__ import annotations

import pytest


def group_names(item: pytest.Item) -> set[str]:
    """The names of the ``xdist_group`` marks on a test (its module's and class's included)."""
    return {str(m.args[0] if m.args else m.kwargs.get("name", "default")) for m in item.iter_markers("xdist_group")}


def group_suffix(item: pytest.Item) -> str | None:
    """``"@a_b"`` for a test marked ``xdist_group("a")`` and ``("b")`` (xdist's rule: the
    sorted names joined by ``_``), None for an ungrouped test."""
    names = group_names(item)
    return "@" + "_".join(sorted(names)) if names else None


def one_group(item: pytest.Item) -> None:
    """A test marked with two groups is in neither (xdist's group is their joined names, ``"a_b"``):
    it loses what each group was for, one worker for the loops or one run of a session fixture its
    group shares (``commission_pmma`` ran twice so). Such a test fails at its set-up, by name."""
    if len(names := group_names(item)) > 1:
        pytest.fail(f"{item.nodeid}: in xdist groups {sorted(names)} at once (xdist makes that a group of its "
                    "own); give it one group", pytrace=False)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Before any fixture of the test: :func:`one_group`."""
    one_group(item)


def module_fixture_group(item: pytest.Item) -> str | None:
    """``"module:<path>"`` for an ungrouped test that uses a module-scoped fixture of its own module,
    else None. Under ``--dist loadgroup`` each ungrouped test is a work unit of its own, so two tests
    of one module could land on two workers and build the module's fixture twice (a commissioning
    run, a rendered rig: tens of seconds of CPU); grouped by module they build it once."""
    if group_names(item):
        return None
    info = getattr(item, "_fixtureinfo", None)
    module = getattr(item, "module", None)
    if info is None or module is None:
        return None
    for defs in info.name2fixturedefs.values():
        fd = defs[-1]
        if fd.scope == "module" and getattr(fd.func, "__module__", None) == module.__name__:
            return f"module:{item.nodeid.split('::')[0]}"
    return None


class Schedule:
    """A plugin of one hook that must run before xdist's (the suffix fix below runs after it)."""

    @staticmethod
    @pytest.hookimpl(tryfirst=True)
    def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
        """Before xdist's own hook, on every process alike (the workers' collections must be the same):
        tests marked ``slow`` first (a stable sort: the load scheduler hands out units in this order, so
        the long ones start at once instead of ending the run), and each module fixture's users in one
        group (:func:`module_fixture_group`)."""
        if not getattr(config.option, "loadgroup", False):
            return
        for item in items:
            if (name := module_fixture_group(item)) is not None:
                item.add_marker(pytest.mark.xdist_group(name))
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_configure(config: pytest.Config) -> None:
    """Register :class:`Schedule` beside this module's hooks."""
    config.pluginmanager.register(Schedule(), "drumtwin-xdist-schedule")


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On an xdist worker under ``--dist loadgroup``: each grouped test's node id ends in its group."""
    if not getattr(config.option, "loadgroup", False):
        return
    for item in items:
        suffix = group_suffix(item)
        if suffix is not None and not item.nodeid.endswith(suffix):
            from _pytest.nodeid import coerce_node_id  # pytest >= 9.2 only: older ones got xdist's suffix

            item._id = coerce_node_id(item.nodeid + suffix)
