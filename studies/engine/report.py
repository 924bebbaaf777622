"""Self-contained HTML reports: text, tables and figures (PNG embedded as base64).

Figures are saved at :data:`FIGURE_DPI` and shown at their natural size up to the page's
width, so a figure drawn :data:`PAGE_WIDTH_IN` inches wide or less is not scaled down and
its text keeps the size it was drawn at (10 pt ≈ 14 px).

Every page says under its title what made it (:class:`Provenance`: the package version,
the git commit when known, the date) and, inside :func:`page_context`, whether it is the
quick form of its study and where the index that links it is (a link back).
"""

from __future__ import annotations

import base64
import contextlib
import datetime as dt
import functools
import html
import io
import subprocess
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version
from pathlib import Path

from scenes.render_cache import atomic_write_bytes

__all__ = [
    "FIGURE_DPI",
    "PACKAGE",
    "PAGE_WIDTH_IN",
    "PageContext",
    "Provenance",
    "Report",
    "join_words",
    "meta_line",
    "page_context",
    "provenance",
]

FIGURE_DPI = 100
"""Resolution of embedded figures, pixels per inch."""
PAGE_WIDTH_IN = 11.0
"""Width of the page's text column at :data:`FIGURE_DPI`, inches (1100 px)."""

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1100px; color: #222; line-height: 1.45;
       padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.3em; }
h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; font-size: 0.9em; margin: 0.5em 0 1em; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; vertical-align: top; }
th { background: #f3f3f3; }
td:first-child, th:first-child { text-align: left; }
table.keys td:nth-child(-n+3) { white-space: nowrap; }
table.answers { font-size: 0.95em; width: 100%; }
table.answers td, table.answers th { text-align: left; white-space: normal; }
.lead { background: #f4f8fb; border-left: 4px solid #3b6ea5; padding: 0.6em 1em; margin: 0.8em 0; }
.lead p { margin: 0.3em 0; }
figure { margin: 1em 0; } figcaption { font-size: 0.9em; color: #555; }
img { max-width: 100%; } .note { color: #555; font-size: 0.9em; }
.meta { color: #555; font-size: 0.85em; margin: 0 0 1em; }
"""

PACKAGE = "beacon-sim"
"""The distribution whose version the pages name."""


@dataclass(frozen=True)
class Provenance:
    """What made a page: ``version`` of the package, ``commit`` (short git hash; None when
    unknown: no git, or not a checkout) and ``date`` (ISO, UTC)."""

    version: str
    commit: str | None
    date: str

    def text(self) -> str:
        """ "beacon-sim 0.1.0, commit 8143c1d, 2026-12-02" (no commit when it is unknown)."""
        commit = f", commit {self.commit}" if self.commit else ", commit unknown"
        return f"{PACKAGE} {self.version}{commit}, {self.date}"

    def to_dict(self) -> dict:
        """The fields, for JSON."""
        return {"version": self.version, "commit": self.commit, "date": self.date}


@functools.cache
def _version() -> str:
    try:
        return package_version(PACKAGE)
    except PackageNotFoundError:
        return "unknown version"


@functools.cache
def _commit() -> str | None:
    """The short hash of the checkout this package runs from; None without git, outside a
    checkout, or in a checkout of another project (an installed copy inside someone's repo)."""
    here = Path(__file__).resolve().parent
    try:
        done = subprocess.run(
            ["git", "rev-parse", "--show-toplevel", "--short=12", "HEAD"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    lines = done.stdout.split()
    if done.returncode != 0 or len(lines) != 2:
        return None
    top, commit = Path(lines[0]), lines[1]
    try:
        ours = f'name = "{PACKAGE}"' in (top / "pyproject.toml").read_text()
    except OSError:
        ours = False
    return commit if ours else None


def provenance(today: dt.date | None = None) -> Provenance:
    """The running package's :class:`Provenance` (``today``: the date to state, default today, UTC)."""
    day = today or dt.datetime.now(dt.UTC).date()
    return Provenance(version=_version(), commit=_commit(), date=day.isoformat())


@dataclass(frozen=True)
class PageContext:
    """What every page written inside :func:`page_context` states: ``quick`` (True: the quick
    form of its study; None: not said), ``index_href`` (the index page, relative to the page;
    None: no link back) and ``provenance`` (None: :func:`provenance` at writing)."""

    quick: bool | None = None
    index_href: str | None = None
    provenance: Provenance | None = None


_CONTEXT: ContextVar[PageContext | None] = ContextVar("page_context", default=None)


@contextlib.contextmanager
def page_context(
    quick: bool | None = None, index_href: str | None = None, provenance: Provenance | None = None
) -> Iterator[PageContext]:
    """Pages written inside say ``quick`` form, link back to ``index_href`` and state ``provenance``."""
    token = _CONTEXT.set(PageContext(quick=quick, index_href=index_href, provenance=provenance))
    try:
        yield _CONTEXT.get() or PageContext()
    finally:
        _CONTEXT.reset(token)


def join_words(words: Sequence[str]) -> str:
    """Words as a sentence lists them: "a", "a and b", "a, b and c".

    >>> join_words(["housing", "paper_colour", "glare_on"])
    'housing, paper_colour and glare_on'
    """
    words = list(words)
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def meta_line(context: PageContext | None = None) -> str:
    """The line under a page's title (markup): "← index · quick form · beacon-sim 0.1.0, commit …, date"."""
    ctx = context or _CONTEXT.get() or PageContext()
    parts = []
    if ctx.index_href:
        parts.append(f"<a href='{html.escape(ctx.index_href)}'>← index of the main job</a>")
    if ctx.quick:
        parts.append("quick form (the main job's small grid)")
    parts.append(html.escape((ctx.provenance or provenance()).text()))
    return f"<p class='meta'>{' · '.join(parts)}</p>"


@dataclass
class Report:
    """An HTML report built section by section."""

    title: str
    parts: list[str] = field(default_factory=list)

    def heading(self, text: str) -> None:
        """A section heading."""
        self.parts.append(f"<h2>{html.escape(text)}</h2>")

    def text(self, text: str, note: bool = False) -> None:
        """A paragraph (escaped)."""
        cls = ' class="note"' if note else ""
        self.parts.append(f"<p{cls}>{html.escape(text)}</p>")

    def lead(self, paragraphs: list[str]) -> None:
        """The report's answer, set apart at the top: paragraphs of plain text (escaped)."""
        body = "".join(f"<p>{html.escape(p)}</p>" for p in paragraphs)
        self.parts.append(f'<div class="lead">{body}</div>')

    def html(self, markup: str) -> None:
        """Markup built by the caller (it escapes any text it puts in)."""
        self.parts.append(markup)

    def table(
        self,
        frame,
        caption: str | None = None,
        float_format: str = "{:.3g}",
        labels: Mapping[str, str] | None = None,
        css_class: str | None = None,
        formats: Mapping[str, str | Callable[[object], str]] | None = None,
    ) -> None:
        """A pandas DataFrame as a table.

        Parameters
        ----------
        frame : the rows; every row is labelled by its own columns (no index is shown).
        caption : bold line above the table.
        float_format : format of float cells.
        labels : column name → header text (units in the header); columns not named keep
            their names.
        css_class : class of the table element: "keys" keeps the first three columns (the
            row's labels) on one line; None (the default) lets every cell wrap.
        formats : column name → format of its cells (e.g. ``"{:g}"``, or a function of the
            value), overriding ``float_format``; missing values show as "–".
        """
        if caption:
            self.parts.append(f"<p><b>{html.escape(caption)}</b></p>")
        shown = frame.copy()
        for column, fmt in (formats or {}).items():
            if column in shown:
                render = fmt if callable(fmt) else fmt.format
                shown[column] = [render(v) if v == v and v is not None else "–" for v in shown[column]]
        shown = shown.rename(columns=dict(labels)) if labels else shown
        classes = [css_class] if css_class else None
        self.parts.append(
            shown.to_html(index=False, float_format=float_format.format, na_rep="–", border=0, classes=classes)
        )

    def figure(self, fig, caption: str) -> None:
        """A matplotlib figure, embedded as PNG at :data:`FIGURE_DPI`; the figure is closed."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=FIGURE_DPI, bbox_inches="tight")
        plt.close(fig)
        self.image_png(buf.getvalue(), caption)

    def image_png(self, png: bytes, caption: str) -> None:
        """PNG bytes, embedded."""
        data = base64.b64encode(png).decode()
        self.parts.append(
            f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )

    def write(self, path: Path) -> Path:
        """Write the report atomically, its :func:`meta_line` under the title."""
        doc = (
            f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(self.title)}</title>"
            f"<style>{_STYLE}</style></head><body><h1>{html.escape(self.title)}</h1>{meta_line()}"
            f"{''.join(self.parts)}</body></html>"
        )
        atomic_write_bytes(Path(path), doc.encode())
        return Path(path)
