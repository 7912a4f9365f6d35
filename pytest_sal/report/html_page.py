"""The shell every HTML page of pytest-sal shares (the outcome report, the experiment page): one
self-contained document (inline CSS, no script, no network resources) written with its pictures
under ``assets/`` into a staging folder that replaces the old page at once, links relative to
the page, text escaped, and the common style sheet."""

from __future__ import annotations

import html
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import quote

from sal_adapters.common.atomic import Replacement

__all__ = ["REPORT_CSS", "asset_src", "esc", "html_page", "page_folder"]


@contextmanager
def page_folder(directory: Path) -> Iterator[Path]:
    """``with page_folder(directory) as folder:`` write ``index.html`` and ``assets/`` into
    ``folder`` (a staging folder, ``assets/`` already made); when the block ends without error
    both replace those in ``directory`` together, even an empty ``assets/`` (an earlier page's
    pictures go); the other files in ``directory`` stay."""
    with Replacement() as outputs:
        folder = outputs.entries(directory)
        (folder / "assets").mkdir()
        yield folder


def asset_src(path: Path, directory: Path) -> str:
    """``path`` relative to the page's ``directory``, URL-quoted and escaped for an attribute."""
    return esc(quote(path.relative_to(directory).as_posix()))


def esc(text: object) -> str:
    """``text`` escaped for HTML text and attribute values."""
    return html.escape(str(text), quote=True)


def html_page(title: str, css: str, body: str) -> str:
    """A whole HTML document: UTF-8, a responsive viewport, ``title`` (escaped here), ``css``
    in a style element and ``body`` (HTML) as the body."""
    return _DOCUMENT.format(title=esc(title), css=css, body=body)


_DOCUMENT = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>{css}</style>
</head>
<body>
{body}
</body>
</html>
"""


REPORT_CSS = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1f2328;
  margin: 0 auto; padding: 1.5em 2em 4em; max-width: 1200px; }
h1 { margin: 0 0 .2em; font-size: 1.6em; }
h2 { font-size: 1.15em; margin: 0 0 .6em; display: flex; align-items: center; gap: .6em; }
h3 { font-size: 1em; margin: 1.2em 0 .4em; }
.headline { font-size: 1.1em; font-weight: 600; margin: .2em 0 1em; }
.where, .dim { color: #656d76; }
code { font: 12.5px ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; background: #f3f4f6;
  padding: .1em .35em; border-radius: 4px; word-break: break-all; }
table { border-collapse: collapse; margin: .5em 0 1em; }
th, td { padding: .3em .7em; border-bottom: 1px solid #e5e7eb; text-align: left; vertical-align: top; }
th { background: #f6f8fa; font-weight: 600; white-space: nowrap; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.summary td:first-child { max-width: 28em; overflow-wrap: anywhere; }
table.summary a { color: inherit; }
table.trials tr.failed td:nth-child(3) { color: #b42318; font-weight: 600; }
table.trials tr.passed td:nth-child(3) { color: #1a7f37; }
section.test { border: 1px solid #d0d7de; border-left: 6px solid #1a7f37; border-radius: 6px;
  padding: 1em 1.3em; margin: 1.6em 0; }
section.test.failed, section.test.regressed { border-left-color: #cf222e; }
section.test.flaky, section.test.inconclusive { border-left-color: #bf8700; }
.id { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; font-weight: 500; overflow-wrap: anywhere; }
dl { display: grid; grid-template-columns: max-content 1fr; gap: .25em 1em; margin: 0 0 1em; }
dt { color: #656d76; }
dd { margin: 0; }
.bad { color: #b42318; font-weight: 600; }
.badge { display: inline-block; padding: .1em .6em; border-radius: 1em; font-size: 12px; font-weight: 700;
  text-transform: uppercase; letter-spacing: .03em; color: #fff; background: #1a7f37; white-space: nowrap; }
.badge.failed { background: #cf222e; }
.badge.regressed { background: #8250df; }
.badge.flaky, .badge.inconclusive { background: #bf8700; }
img.plot { display: block; max-width: 100%; height: auto; border: 1px solid #e5e7eb; border-radius: 4px; }
.gallery { display: flex; flex-wrap: wrap; gap: .8em; }
.gallery figure { margin: 0; border: 3px solid #1a7f37; border-radius: 5px; padding: 3px; background: #fff; }
.gallery figure.failed { border-color: #cf222e; }
.gallery img { display: block; width: 220px; height: auto; }
.gallery.trajectory img { width: 320px; }
.gallery figcaption { text-align: center; font-size: 12.5px; padding-top: .2em; }
.gallery .none { width: 220px; height: 80px; display: flex; align-items: center; justify-content: center;
  color: #656d76; background: #f6f8fa; font-size: 12px; }
"""
