"""Physics-step cost side by side in one process: MuJoCo's bare chain, our tether, the capture system.

Every case is timed in interleaved rounds (each round times every case once) and the per-case
minimum over rounds is reported, so the ratios compare runs made under the same machine load:

* ``mujoco``: MuJoCo's bare 30-rod chain (30 capsules, one ball joint each, no aerodynamics), RK4
  at dt = 0.01 s, ``mujoco.mj_step`` (the issue's reference; skipped when mujoco is not installed).
* ``tether n=30``: Table 3's towed tether with the stand-in body, aerodynamics on every segment,
  RK4 at 0.01 s (``accd_gym.towed_tether().advance``); ``tether n=300`` at 0.005 s (RK4 at 0.01 s
  is outside its stability region for 0.83 m segments).
* ``capture exact``: the whole capture system (tether n = 30, ACCD 6-DoF with aerodynamics, 8 deg
  wake with turbulence, boom, capture check) under the exact air scheme of the first releases
  (sampled at every RK4 stage, Box-Muller, one turbulence stream), ``CaptureSim.step(steps=N)``;
  ``capture fast``: per-step sampling, ziggurat normals, per-lane turbulence streams;
  ``capture (default)``: the default configuration (the fast scheme).

    python scripts/bench_physics.py [--rounds 7] [--seconds 0.5] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import accd_gym

FAST = {"wake": {"sampling": "per_step"}, "turbulence": {"normal_sampler": "ziggurat", "lane_streams": "per_lane"}}
EXACT = {"wake": {"sampling": "per_stage"}, "turbulence": {"normal_sampler": "box_muller", "lane_streams": "shared"}}


def mujoco_chain(n: int = 30, length: float = 250.0):
    """A MuJoCo model and data of a bare chain of ``n`` capsules with ball joints, RK4 at 0.01 s."""
    import mujoco

    seg = length / n
    body = ""
    for k in reversed(range(n)):
        inner = body
        body = (
            f'<body pos="{seg if k else 0} 0 0"><joint type="ball"/>'
            f'<geom type="capsule" fromto="0 0 0 {seg} 0 0" size="0.012" density="1000"/>{inner}</body>'
        )
    xml = (
        '<mujoco><option timestep="0.01" integrator="RK4"/><worldbody>'
        f"{body}</worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[:4] = [0.9238795, 0.0, 0.3826834, 0.0]  # the first rod 45 deg down: it swings
    return mujoco, model, data


def cases():
    """(name, function(steps) that advances that many physics steps) for every case."""
    out = []
    try:
        mujoco, model, data = mujoco_chain()

        def mj(steps: int) -> None:
            for _ in range(steps):
                mujoco.mj_step(model, data)

        out.append(("mujoco bare chain n=30", mj))
    except ImportError:
        pass
    tether = accd_gym.towed_tether()
    tether.advance(20.0)
    out.append(("tether n=30", lambda steps: tether.advance(steps * tether.time_step)))
    long = accd_gym.Tether({"segments": 300, "time_step": 0.005, "tip_mass": 50.0}, preset="table3")
    long.tow(airspeed=185.0, altitude=6000.0)
    long.set_surroundings(tip_drag_area=0.042)
    long.advance(5.0)
    out.append(("tether n=300 (dt 0.005)", lambda steps: long.advance(steps * long.time_step)))
    exact = accd_gym.CaptureSim(EXACT, seed=1, wake_seed=42)
    exact.settle(20.0)
    out.append(("capture exact", lambda steps: exact.step(steps=steps)))
    fast = accd_gym.CaptureSim(FAST, seed=1, wake_seed=42)
    fast.settle(20.0)
    out.append(("capture fast", lambda steps: fast.step(steps=steps)))
    default = accd_gym.CaptureSim(seed=1, wake_seed=42)
    default.settle(20.0)
    out.append(("capture (default)", lambda steps: default.step(steps=steps)))
    return out


def measure(rounds: int, seconds: float) -> dict[str, float]:
    """Minimum over ``rounds`` of the cost per physics step (s) of every case."""
    todo = cases()
    steps = {}
    for name, fn in todo:  # calibrate: steps that take about `seconds`
        n = 50
        while True:
            t = time.perf_counter()
            fn(n)
            dt = time.perf_counter() - t
            if dt > 0.05:
                steps[name] = max(1, int(n * seconds / dt))
                break
            n *= 4
    best = {name: float("inf") for name, _ in todo}
    for _ in range(rounds):
        for name, fn in todo:
            t = time.perf_counter()
            fn(steps[name])
            best[name] = min(best[name], (time.perf_counter() - t) / steps[name])
    return best


def main() -> None:
    """Prints the cost per step of every case and the ratios the benchmarks track."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--seconds", type=float, default=0.5, help="per case and round")
    p.add_argument("--json", help="write the results here")
    a = p.parse_args()
    best = measure(a.rounds, a.seconds)
    for name, s in best.items():
        print(f"{name:<28} {s * 1e6:9.2f} us per step")
    t30 = best["tether n=30"]
    ratios = {
        "tether n=300 / n=30 (per step)": best["tether n=300 (dt 0.005)"] / t30,
        "capture exact / tether": best["capture exact"] / t30,
        "capture default / tether": best["capture (default)"] / t30,
        "capture fast / tether": best["capture fast"] / t30,
    }
    mj = best.get("mujoco bare chain n=30")
    if mj:
        ratios["mujoco / tether"] = mj / t30
        ratios["mujoco / capture default"] = mj / best["capture (default)"]
        ratios["mujoco / capture exact"] = mj / best["capture exact"]
        ratios["mujoco / capture fast"] = mj / best["capture fast"]
    for name, r in ratios.items():
        print(f"{name:<32} {r:7.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"machine": platform.processor() or platform.machine(), "us_per_step": {k: v * 1e6 for k, v in best.items()}, "ratios": ratios}, f, indent=2)


if __name__ == "__main__":
    main()
