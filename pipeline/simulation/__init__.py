"""The simulated lab: a perturbed machine measured like a metrology lab (:class:`Testbed`), and
the seeded scenarios of the discovery studies (effects drawn, poses drawn, recordings made), and a
calibration's identified machine written as MuJoCo's MJCF (:mod:`pipeline.simulation.mjcf_export`).
MuJoCo itself (building, commanding, settling and reading the machine) lives in :mod:`mjcf`;
this package is imported on first use."""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "testbed": ("Testbed", "Measurements", "SettleError", "SETTLE_MODES"),
    "scenarios": ("DISCOVERY_NOISE", "ScenarioMachine", "SCENARIO_MACHINES", "scenario_machine", "machine_context",
                  "merged_settings", "simulate", "make_recording", "effects_settings", "effect_recording",
                  "LawCase", "LAW_CASES", "law_cases_for", "law_recording", "TEMPERATURE_CHANNEL",
                  "heldout_targets", "command_scenario_machine", "heldout_payloads"),
    "mjcf_export": ("export_mjcf", "mjcf_text", "identified_machine", "IdentifiedMachine"),
})
