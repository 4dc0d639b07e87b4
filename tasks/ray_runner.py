"""Episodes on a Ray cluster (``--ray ADDRESS``; the optional ``cluster`` extra).

One Ray task per config, running the same per-config job as the local workers; results
stream back in completion order. Ray is imported only here, only when asked for.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator, Sequence
from typing import Any

from serpar.calibration.camera_cache import cache_dir
from serpar.errors import ConfigError
from serpar.tasks.episode_config import EpisodeConfig

RAY_MISSING = "--ray needs the cluster extra: pip install 'serpar[cluster]'"


def require_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ConfigError(RAY_MISSING) from None
    return ray


REACH_TIMEOUT_S = 5.0


def check_reachable(address: str) -> None:
    """Fail at once, in one line, when nothing answers at a ``[ray://]HOST:PORT`` address (Ray
    itself retries an unreachable one for minutes); "local" and "auto" are not probed."""
    if address in ("local", "auto"):
        return
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ConfigError(f"--ray {address}: not an address; valid: local, auto, ray://HOST:PORT "
                          "or a cluster's HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=REACH_TIMEOUT_S).close()
    except OSError as exc:
        raise ConfigError(f"--ray {address}: nothing answers at {host}:{port} "
                          f"({exc.strerror or type(exc).__name__})") from None


def _connect(ray: Any, address: str) -> bool:
    """Join `address` ("local": a new instance on this machine, "auto": the running cluster,
    "ray://host:port": a remote one); True if this call started Ray here."""
    if ray.is_initialized():  # a caller (or a test) already runs Ray: use it, leave it running
        return False

    # workers on this machine then find the driver's calibration cache and source tree; other
    # machines need the same paths (a shared SERPAR_CACHE) or calibrate there once
    env = {"SERPAR_CACHE": str(cache_dir().absolute())}
    if os.environ.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.pathsep.join(os.path.abspath(p) for p in os.environ["PYTHONPATH"].split(os.pathsep))
    extra = {"include_dashboard": False} if address == "local" else {}
    try:
        ray.init(address=address, runtime_env={"env_vars": env}, log_to_driver=False, **extra)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ConfigError(f"--ray {address}: cannot connect ({first}); valid: local, auto, "
                          "ray://HOST:PORT or a cluster's HOST:PORT") from None
    return True


def ray_map(job: Any, args: Sequence[tuple[Any, ...]], address: str, shared: Any = None
            ) -> Iterator[tuple[int, Any, BaseException | None]]:
    """``job(shared, *args[i])`` (``shared`` sent to the cluster once) as one Ray task each,
    one CPU: yields (i, result, None) as tasks finish, or (i, None, error) for a task that died
    (e.g. its worker killed). On exit (done, Ctrl-C, error) the pending tasks are cancelled
    and a Ray instance started here is shut down."""
    ray = require_ray()
    started = _connect(ray, address)
    tasks: dict[Any, int] = {}
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(job)
        shared_ref = ray.put(shared)
        tasks = {remote.remote(shared_ref, *a): i for i, a in enumerate(args)}
        pending = list(tasks)
        while pending:
            (ref,), pending = ray.wait(pending, num_returns=1)
            i = tasks.pop(ref)
            try:
                yield i, ray.get(ref), None
            except ray.exceptions.RayError as exc:
                yield i, None, exc
    finally:
        for ref in tasks:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


def _call(job: Any, cfg: EpisodeConfig, label: str | None) -> list[dict[str, object]]:
    return job(cfg, None, label)


def ray_results(configs: Sequence[EpisodeConfig], labels: Sequence[str | None], job: Any,
                address: str) -> Iterator[list[dict[str, object]]]:
    """Each config's records as its task finishes (a task that dies gives an error record)."""
    for i, records, exc in ray_map(_call, list(zip(configs, labels)), address, shared=job):
        if exc is not None:
            tag = {} if labels[i] is None else {"config": labels[i]}
            records = [{"kind": "error", "episode_seed": configs[i].seed, "error": f"{type(exc).__name__}: "
                        f"{(str(exc).strip().splitlines() or [''])[0]}", **tag}]
        yield records
