"""The report of a calibration or a discovery: its typed model (:mod:`.model`), a run's made from
its objects (:mod:`.calibration`; a discovery's: :mod:`.discovery`), the words of it
(:mod:`.text`: the terminal summary, the Rerun markdown, the phrases of the page; the verdict's words
per cause in :mod:`.verdict_words`) and its HTML page (:mod:`.html`).

The names below are imported from their modules when first used.
"""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "model": ("Report", "REPORT_KEY", "OUTPUT_KEYS"),
    "calibration": ("calibration_report", "calibration_file_report"),
    "discovery": ("discovery_report",),
    "text": ("terminal_lines", "report_markdown", "verdict_words", "model_words"),
    "html": ("render_html", "write_report"),
})
