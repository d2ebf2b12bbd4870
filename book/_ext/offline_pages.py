"""Sphinx extension of this book: pages that open clean, offline, from ``file://``.

* Thebe (live code cells) is off in ``_config.yml``, yet sphinx-thebe still
  adds its configuration script to every page, twice (a console error:
  ``THEBE_JS_URL`` declared twice) and with a web address in it.  Its
  scripts and stylesheet are dropped from the pages.
* The theme logs an error when no colour mode is set: the book sets light.
* Search result summaries are fetched page by page, which a browser refuses
  under ``file://``: the results list the pages without them
  (``html_show_search_summary``).
"""

from __future__ import annotations

from typing import Any


def _not_thebe(asset: Any) -> bool:
    name = str(getattr(asset, "filename", "") or "")
    body = str(getattr(asset, "attributes", {}).get("body", ""))
    return "thebe" not in name and "THEBE_JS_URL" not in body


def _page_context(app: Any, pagename: str, templatename: str, context: dict[str, Any], doctree: Any) -> None:
    context["script_files"] = [s for s in context.get("script_files", []) if _not_thebe(s)]
    context["css_files"] = [s for s in context.get("css_files", []) if _not_thebe(s)]
    context["default_mode"] = context.get("default_mode") or "light"


def _config_inited(app: Any, config: Any) -> None:
    config.html_show_search_summary = False


def setup(app: Any) -> dict[str, Any]:
    app.connect("config-inited", _config_inited)
    app.connect("html-page-context", _page_context, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
