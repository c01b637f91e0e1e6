"""The report's HTML: the Jinja2 template ``templates/report.html.j2`` filled with what
:mod:`pipeline.report.sections` read, and how values are written on it (:func:`text`, :func:`duration`).

Everything the template prints is HTML-escaped (``html.escape``, quotes too) unless it is markup the template
itself made, so text from a stage's files never becomes markup."""

from __future__ import annotations

import datetime
import html
import math
from collections.abc import Sequence
from functools import cache
from typing import Any

import jinja2
from markupsafe import Markup

TEMPLATE = "report.html.j2"


def text(value: Any, digits: int = 4) -> str:
    """A value as plain text (not escaped): numbers to ``digits`` significant figures, None/NaN as a dash,
    booleans as yes/no, lists and dicts inline."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.{digits}g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(text(v, digits) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {text(v, digits)}" for k, v in value.items())
    return str(value)


def duration(seconds: Any) -> str:
    """Seconds as ``12.3 s`` under a minute, else ``h:mm:ss``; a dash when not a number."""
    if seconds is None or not isinstance(seconds, int | float) or not math.isfinite(seconds):
        return "—"
    if seconds < 60:
        return f"{seconds:.1f} s"
    return str(datetime.timedelta(seconds=round(seconds)))


def _escaped(value: Any) -> Markup:
    # html.escape rather than markupsafe's: quotes as &quot; / &#x27;, as the page always wrote them
    return value if isinstance(value, Markup) else Markup(html.escape(str(value), quote=True))


@cache
def environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("pipeline.report", "templates"), autoescape=True, finalize=_escaped,
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["text"] = text
    env.tests["numeric"] = lambda v: isinstance(v, int | float) and not isinstance(v, bool)
    env.tests["omitted"] = lambda v: v is ...  # a table row left out
    return env


def render(*, capture: str, results: str, created: str, sections: Sequence[dict[str, Any]],
           problems: Sequence[str]) -> str:
    """The page: a header, the overview of ``sections`` (each a dict: ``id``, ``title``, ``status``, ``summary``
    and what :func:`pipeline.report.sections.section` read) and the sections, in order."""
    return environment().get_template(TEMPLATE).render(
        capture=capture, results=results, created=created, sections=sections, problems=problems)
