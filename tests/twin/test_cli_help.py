"""The CLI's help says what its source says: typer renders help with rich markup, in which a
TOML table name such as ``[drum]`` is a style tag and vanished from ``--help`` ("the twin's
mixer (, [])"). A bracket meant literally is written ``\\[``."""

from __future__ import annotations

import re

from rich.text import Text

from tests.cli import cli
from twin.cli import _command


def _texts(cmd, path: tuple[str, ...] = ()) -> list[tuple[str, str, str]]:
    """(command path, parameter or "help", help text) of every command and parameter."""
    out = [(" ".join(path), "help", cmd.help or "")]
    out += [(" ".join(path), p.name or "", getattr(p, "help", None) or "") for p in cmd.params]
    for name, sub in getattr(cmd, "commands", {}).items():
        out += _texts(sub, (*path, name))
    return out


def test_no_help_text_loses_characters_to_rich_markup() -> None:
    texts = _texts(_command())
    assert len(texts) > 100  # the whole tree was walked
    lost = [(p, n, t) for p, n, t in texts if Text.from_markup(t).plain != t.replace("\\[", "[")]
    assert not lost, lost


def test_the_rendered_help_names_the_toml_tables() -> None:
    for args, needle in ((("classes", "suggest"), "mixer ([drum], [[particles]])"),
                         (("mill", "set-rpm"), "[drive]"), (("run",), "[drum], [[particles]]")):
        r = cli(*args, "--help")
        assert r.code == 0, r.err
        flat = re.sub(r"[\s│]+", " ", r.out)  # panels' borders and wrapping out
        assert needle in flat, (args, flat[:3000])
