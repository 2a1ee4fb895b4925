"""The connection to a Ray cluster that RLlib training, Ray Tune sweeps and distributed
evaluation share (``pip install 'accd-gym[ray]'``). Importing this module does not import Ray."""

from __future__ import annotations

from typing import Any, Optional


def _ray() -> Any:
    """The ``ray`` module, or a ModuleNotFoundError saying which extra brings it."""
    try:
        import ray
    except ModuleNotFoundError as e:
        raise ModuleNotFoundError(f"distributed runs need Ray ({e}): pip install 'accd-gym[ray]'", name="ray") from e
    return ray


def connect(address: Optional[str] = "local", *, num_cpus: Optional[int] = None) -> Any:
    """Connects to Ray unless already connected; returns the ``ray`` module.

    ``address``: ``"local"`` or None starts a Ray instance on this machine (``num_cpus`` of
    its cores, default all), ``"auto"`` joins the cluster this machine is a node of, and
    ``"HOST:PORT"`` (or ``ray://HOST:PORT``) the cluster whose head listens there.
    """
    ray = _ray()
    if ray.is_initialized():
        return ray
    if address in (None, "", "local"):
        # Bound to loopback: a local instance needs no other interface.
        ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False, _node_ip_address="127.0.0.1")
    else:
        ray.init(address=address, log_to_driver=False)
    return ray


__all__ = ["connect"]
