"""Every module of fleetlink imports on its own, in an interpreter that imported no other part of
fleetlink first: an import cycle that only works in one order fails here (docs/architecture.md).

One child process per module, forked from a parent that loaded the third-party libraries once
(so each child pays only for fleetlink's own modules), as many at once as there are cores.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from tests.paths import ROOT
from tests.unit.test_layers import modules

CHILD = textwrap.dedent(
    """
    import importlib, json, os, sys, traceback
    for name in ("zenoh", "confluent_kafka", "confluent_kafka.schema_registry", "fastapi", "pydantic",
                 "numpy", "rosbags.typesys", "fastavro", "prometheus_client", "httpx", "yaml",
                 "jinja2", "uvicorn", "cryptography.x509", "starlette"):
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    assert not [m for m in sys.modules if m == "fleetlink" or m.startswith("fleetlink.")]
    failures = {}
    running = []
    def collect():
        module, pid, read = running.pop(0)
        out = b""
        while chunk := os.read(read, 65536):
            out += chunk
        os.close(read)
        os.waitpid(pid, 0)
        if out:
            failures[module] = out.decode()
    for module in json.loads(sys.stdin.read()):
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(read)
            try:
                importlib.import_module(module)
                message = b""
            except BaseException:
                message = traceback.format_exc().encode()[-3000:]
            os.write(write, message)
            os._exit(0)
        os.close(write)
        running.append((module, pid, read))
        if len(running) >= max(2, os.cpu_count() or 1):
            collect()
    while running:
        collect()
    print(json.dumps(failures))
    """
)


def test_every_module_imports_alone_in_a_fresh_interpreter() -> None:
    names = sorted(name for name in modules() if not name.endswith("__main__"))
    done = subprocess.run(
        [sys.executable, "-c", CHILD],
        input=json.dumps(names),
        capture_output=True,
        text=True,
        cwd=ROOT / "tests",
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    failures: dict[str, str] = json.loads(done.stdout.strip().splitlines()[-1])
    assert failures == {}, "\n\n".join(f"{name}:\n{trace}" for name, trace in failures.items())
