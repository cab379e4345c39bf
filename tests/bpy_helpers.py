"""Run a script in a fresh Python process (fresh bpy) and read back the JSON it reports.

The script reports by printing one line `RESULT <json>` to stdout; bpy writes its own noise to
stdout/stderr, which is kept for the assertion message.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

RESULT_PREFIX = "RESULT "

# Pasted into every child script: report(obj) prints the line run_bpy_script() looks for;
# open_blend(path) opens a .blend as a farm worker would (bpy's own OpenImageIO and oslquery,
# never the add-on) and returns its scene.
REPORT_FN = textwrap.dedent('''
    def report(obj):
        import json, sys
        sys.stdout.write("\\nRESULT " + json.dumps(obj) + "\\n")
        sys.stdout.flush()


    def open_blend(path):
        import bpy
        if hasattr(bpy.utils, "expose_bundled_modules"):
            bpy.utils.expose_bundled_modules()
        bpy.ops.wm.open_mainfile(filepath=path)
        return bpy.context.scene
''')


def run_bpy_script(source: str, workdir: Path, *args: str, env: dict | None = None,
                   timeout: float = 120) -> dict:
    """Write `source` to workdir/child.py, run it with this interpreter (cwd=workdir, so the
    repository is not importable by accident), and return the parsed RESULT line."""
    script = Path(workdir) / "child.py"
    script.write_text(REPORT_FN + textwrap.dedent(source))
    full_env = dict(os.environ)
    full_env.pop("PYTHONPATH", None)
    full_env.update(env or {})
    proc = subprocess.run([sys.executable, str(script), *args], cwd=workdir, env=full_env,
                          capture_output=True, text=True, timeout=timeout)
    lines = [line for line in proc.stdout.splitlines() if line.startswith(RESULT_PREFIX)]
    log = f"exit {proc.returncode}\n--- stdout\n{proc.stdout[-4000:]}\n--- stderr\n{proc.stderr[-4000:]}"
    assert proc.returncode == 0, f"child process failed: {log}"
    assert len(lines) == 1, f"expected one RESULT line: {log}"
    result = json.loads(lines[0][len(RESULT_PREFIX):])
    result["_log"] = log
    return result
