"""How gravity and payload spoil a purely kinematic calibration of the hexapod.

Runs ``pipeline.run`` on the paper scenario (the hexapod's 10 reference poses) with gravity on
and several payloads (and the default servo stiffness of 2e5 N/m), and prints how far the
settled poses depart from the kinematics and what that does to the held-out error after a
kinematic calibration.
``python benchmarks/gravity_study.py [--noise-mm 0]``.
"""

from __future__ import annotations

import argparse
import tempfile

from pipeline.run import run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--noise-mm", default="0.001")
    ap.add_argument("--poses", default="reference", help="as pipeline.run --poses")
    a = ap.parse_args()
    print(f"noise {a.noise_mm} mm, poses {a.poses}")
    print("| gravity | payload kg | departure from kinematics, mean / max um | held-out before um | after um | improvement | param RMS um |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as out:
        for grav, payload in [(False, 0.0), (True, 0.0), (True, 1.0), (True, 5.0), (True, 10.0), (True, 20.0)]:
            argv = ["--out", out, "--name", f"g{grav}_{payload}", "--quiet", "--payload-kg", str(payload),
                    "--noise-mm", a.noise_mm, "--poses", a.poses] + (["--gravity"] if grav else [])
            try:
                s = run(argv).summary
            except ValueError as exc:  # the identified geometry cannot command the held-out poses
                print(f"| {'on' if grav else 'off'} | {payload:g} | calibration failed: {exc} |||||")
                continue
            d, h = s["kinematic_departure"]["position_mm"], s["heldout_position_error_mm"]
            print(f"| {'on' if grav else 'off'} | {payload:g} | {1e3 * d['mean']:.2f} / {1e3 * d['max']:.2f} | "
                  f"{1e3 * h['before']:.2f} | {1e3 * h['after']:.3f} | {h['before'] / h['after']:.1f}x | "
                  f"{1e3 * s['parameter_error']['rms_mm']:.1f} |")


if __name__ == "__main__":
    main()
