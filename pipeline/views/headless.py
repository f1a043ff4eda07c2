"""The default view of a recording as a PNG (:func:`snapshot`; the command ``python -m pipeline.snapshot``).

Starts the Rerun viewer headless (``rerun --headless``: no window, no display needed) on a free
local port, opens the recording with its default blueprint, waits until it is loaded and drawn,
and saves a screenshot. Needs a Vulkan adapter; on a machine without a GPU the software renderer
of Debian's ``mesa-vulkan-drivers`` (lavapipe) is enough. Without one the command exits 2 with a
one-line message.

With several files the viewer shows the last one opened (the others stay loaded, each with its
own layout: a way to check that recordings of different tools open together).
"""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pipeline.formats import writing

__all__ = ["snapshot", "renderer_available", "viewer_executable", "SnapshotError", "DEFAULT_SIZE"]

#: Logical window size of the headless viewer (points; one pixel a point).
DEFAULT_SIZE = "1600x900"
#: Vulkan driver manifests (a software or hardware ICD must be installed for the viewer to draw).
VULKAN_ICD_GLOBS = ("/usr/share/vulkan/icd.d/*.json", "/etc/vulkan/icd.d/*.json",
                    "/usr/local/share/vulkan/icd.d/*.json")
#: Seconds the viewer's start-up notifications stay on screen; the picture is taken after them.
NOTIFICATION_S = 7.0


class SnapshotError(RuntimeError):
    """The recording could not be rendered (the message says why, in one line)."""


def viewer_executable() -> str | None:
    """The ``rerun`` viewer of this Python's environment (beside its interpreter, so that an
    environment that is not activated still finds its own), else the one on PATH, else None."""
    beside = Path(sys.executable).with_name("rerun")
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    return shutil.which("rerun")


def renderer_available() -> str | None:
    """None if the headless viewer can draw here, else why not (one line)."""
    if viewer_executable() is None:
        return "the rerun viewer executable is not installed beside this Python or on PATH (pip install rerun-sdk)"
    if os.environ.get("VK_ICD_FILENAMES") or os.environ.get("VK_DRIVER_FILES"):
        return None
    if not any(glob.glob(g) for g in VULKAN_ICD_GLOBS):
        return ("no Vulkan driver is installed, so the headless viewer cannot draw "
                "(apt-get install mesa-vulkan-drivers gives the software renderer lavapipe)")
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _connect(url: str, proc: subprocess.Popen, timeout_s: float):
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + timeout_s
    while True:
        if proc.poll() is not None:
            raise SnapshotError(f"the headless viewer exited at start (code {proc.returncode}): "
                                "no usable graphics adapter?")
        try:
            client = ViewerClient.connect(url)
            client.get_state()
            return client
        except Exception:  # noqa: BLE001 - not listening yet
            if time.monotonic() > deadline:
                raise SnapshotError("the headless viewer did not answer in time") from None
            time.sleep(0.2)


def snapshot(paths, out: str | Path, *, size: str = DEFAULT_SIZE, timeout_s: float = 60.0,
             settle_s: float = NOTIFICATION_S, max_size: int | None = None) -> Path:
    """Render the default view of ``paths`` (one ``.rrd`` or several) to the PNG ``out``.

    Raises:
        FileNotFoundError: a recording does not exist.
        SnapshotError: the viewer cannot run or draw here.
    """
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    for p in paths:
        if not p.is_file():
            raise FileNotFoundError(f"no such recording: {p}")
    why = renderer_available()
    if why:
        raise SnapshotError(why)
    port = _free_port()
    env = dict(os.environ, RERUN_APP_ONLY="true")
    home = tempfile.mkdtemp(prefix="rerun-home-")  # the viewer writes state and analytics under HOME
    env.setdefault("XDG_RUNTIME_DIR", home)
    env["HOME"] = home
    log = open(Path(home) / "viewer.log", "w+b")  # noqa: SIM115 - closed in finally
    cmd = [viewer_executable(), "--headless", "--hide-welcome-screen", "--window-size", size, "--port", str(port)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=log,
                            start_new_session=True)
    try:
        return _shoot(proc, port, paths, out, timeout_s=timeout_s, settle_s=settle_s, max_size=max_size)
    except SnapshotError:
        raise
    except Exception as exc:  # noqa: BLE001 - the viewer died or stopped answering: say why
        raise SnapshotError(_why_viewer_failed(log, exc)) from exc
    finally:
        _stop_session(proc)
        log.close()
        shutil.rmtree(home, ignore_errors=True)


def _stop_session(proc: subprocess.Popen) -> None:
    """Stop the viewer and every process it started: the ``rerun`` launcher beside the
    interpreter runs the viewer binary as its child, which outlives a plain ``terminate`` of the
    launcher. The viewer was started in a session of its own, so its process group is signalled."""
    import signal

    for sig, wait_s in ((signal.SIGTERM, 5), (signal.SIGKILL, 5)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:  # the whole group is gone
            break
        try:
            proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            continue
        try:  # the launcher is gone; give the rest of its group a moment
            for _ in range(50):
                os.killpg(proc.pid, 0)
                time.sleep(0.1)
        except ProcessLookupError:
            break


def _why_viewer_failed(log, exc: Exception) -> str:
    """The viewer's panic message if it left one, else the client's error (one line)."""
    log.flush()
    log.seek(0)
    text = log.read().decode(errors="replace")
    for line in text.splitlines():
        if "panicked at" in line:
            return "the viewer crashed: " + line.split("panicked at", 1)[1].strip(" :'")
    return f"the viewer stopped answering ({type(exc).__name__}: {exc})"


def _shoot(proc, port, paths, out, *, timeout_s, settle_s, max_size) -> Path:
    """Open ``paths`` in the running viewer, wait until drawn, save the screenshot to ``out``."""
    client = _connect(f"rerun+http://127.0.0.1:{port}/proxy", proc, timeout_s)
    started = time.monotonic()
    for p in paths:
        client.open(str(p.resolve()))
    deadline = time.monotonic() + timeout_s
    while True:
        state = client.get_state()
        if not state.loading and state.views:
            break
        if time.monotonic() > deadline:
            raise SnapshotError(f"the viewer did not finish loading {', '.join(map(str, paths))} in time")
        time.sleep(0.2)
    time.sleep(max(0.5, settle_s - (time.monotonic() - started)))
    client.take_screenshot(max_size=max_size)  # the first frame after loading can be incomplete
    time.sleep(0.5)
    png = client.take_screenshot(max_size=max_size)
    if not png:
        raise SnapshotError("the viewer returned no picture")
    out = Path(out)
    with writing(out, overwrite=True) as tmp:  # atomic: an interrupted run leaves the earlier picture
        tmp.write_bytes(png)
        _shrink(tmp)
    return out


def _shrink(path: Path) -> None:
    """Re-encode as a 256-colour PNG when Pillow is at hand (UI pictures lose nothing visible)."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(path) as im:
        small = im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(path, format="PNG", optimize=True)

