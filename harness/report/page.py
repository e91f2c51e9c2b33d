"""HTML of the report: one self-contained page (inline CSS and a small sort script, no network)."""

from __future__ import annotations

import html

import pandas as pd

STYLE = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ccc; }
h3 { font-size: 1.05em; margin-top: 1.4em; }
table { border-collapse: collapse; font-size: 0.8em; margin: 0.6em 0; }
th, td { border: 1px solid #ddd; padding: 3px 6px; text-align: left; }
th { background: #f3f3f3; cursor: pointer; user-select: none; }
th.sorted-asc::after { content: " \\25B2"; } th.sorted-desc::after { content: " \\25BC"; }
figure { display: inline-block; margin: 4px; vertical-align: top; text-align: center; }
figcaption { font-size: 0.75em; max-width: 260px; word-wrap: break-word; }
img { image-rendering: pixelated; border: 1px solid #ccc; }
.note { color: #666; font-size: 0.85em; }
"""

SORT_SCRIPT = """
function sortTable(th) {
  const table = th.closest("table"), body = table.tBodies[0];
  const index = Array.from(th.parentNode.children).indexOf(th);
  const asc = !th.classList.contains("sorted-asc");
  table.querySelectorAll("th").forEach(h => h.classList.remove("sorted-asc", "sorted-desc"));
  th.classList.add(asc ? "sorted-asc" : "sorted-desc");
  const key = row => {
    const text = row.children[index].textContent.trim();
    const number = parseFloat(text.replace(/^[^0-9.+-]*/, ""));
    return isNaN(number) ? text : number;
  };
  const rows = Array.from(body.rows);
  rows.sort((a, b) => {
    const x = key(a), y = key(b);
    if (typeof x === "number" && typeof y === "number") return asc ? x - y : y - x;
    return asc ? String(x).localeCompare(String(y)) : String(y).localeCompare(String(x));
  });
  rows.forEach(r => body.appendChild(r));
}
document.querySelectorAll("table.sortable th").forEach(th => th.addEventListener("click", () => sortTable(th)));
"""


def esc(value) -> str:
    return html.escape(str(value), quote=True)


def table(df: pd.DataFrame, sortable: bool = True) -> str:
    """A DataFrame of strings/numbers as an HTML table (sortable by clicking a header)."""
    if df.empty:
        return '<p class="note">(none)</p>'
    head = "".join(f"<th>{esc(c)}</th>" for c in df.columns)
    body = "".join("<tr>" + "".join(f"<td>{esc(_cell(v))}</td>" for v in row) + "</tr>"
                   for row in df.itertuples(index=False))
    cls = ' class="sortable"' if sortable else ""
    return f"<table{cls}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _cell(value) -> str:
    if isinstance(value, float):
        return "-" if value != value else f"{value:.4g}"
    return str(value)


def figure(src: str, caption: str, width: int | None = None) -> str:
    size = f' width="{width}"' if width else ""
    return f'<figure><img src="{esc(src)}" alt="{esc(caption)}"{size}><figcaption>{esc(caption)}</figcaption></figure>'


def page(title: str, sections: list[str]) -> str:
    """The whole document."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{esc(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{esc(title)}</h1>{''.join(sections)}<script>{SORT_SCRIPT}</script></body></html>\n")


__all__ = ["esc", "figure", "page", "table"]
