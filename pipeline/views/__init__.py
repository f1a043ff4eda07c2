"""Views: what a person sees of each tool's results, Rerun files with their default layouts
(one application id per tool and robot), and reading an ``.rrd`` back. Rerun is imported on first
use."""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "charts": ("TOOLS", "application_id", "MACHINE_COLORS", "FLAG_COLOR", "chain_color", "chain_colors", "magnitude_colors",
               "magnification", "nice_step", "log_named_bars", "log_plot", "log_residual_scatter",
               "log_series_by_pose", "chart_view", "save_recording"),
    "run_view": ("log_calibration_run", "blueprint", "run_eye", "run_magnification"),
    "observability": ("log_observability", "log_bars", "bar_values", "log_combinations", "observability_markdown",
                      "observability_views"),
    "discovery_view": ("PLOTTED_QUANTITIES", "quantity_values", "verdict_quantity", "write_discovery_rrd"),
    "headless": ("snapshot", "renderer_available", "viewer_executable", "SnapshotError"),
    "design_view": ("write_design_rrd", "position_columns"),
    "study_view": ("write_study_rrd", "study_markdown"),
    "rrd": ("rrd_entities", "rrd_application_ids", "rrd_blueprint", "empty_views", "rrd_labels"),
})
