"""Times recording and replay: record_episodes against run_episodes on the same 16
episodes (neutral flaps, 2 threads, best of 3), a 70 s episode's page, MP4 and .npz, and one
headless-Chromium screenshot. Prints one line each. Usage: python scripts/bench_replay.py"""
import time, os
from accd_gym.evals.evaluation import run_episodes, load_policy
from accd_gym.replays.recording import record_episodes
from accd_gym.replays.replay import write_replay, write_video
def best(f, n=3):
    ts=[]
    for _ in range(n):
        t=time.perf_counter(); r=f(); ts.append(time.perf_counter()-t)
    return min(ts), r
kw=dict(num_envs=16, num_threads=2)
te,_=best(lambda: run_episodes(load_policy("zero"), 16, **kw))
tr,recs=best(lambda: record_episodes("zero", 16, **kw))
steps=sum(r.steps for r in recs)
print(f"run_episodes 16 zero episodes: {te:.2f} s; record_episodes: {tr:.2f} s ({steps} agent steps)")
r=max(recs, key=lambda r: r.steps)
tw,_=best(lambda: write_replay(r, "/tmp/br/bench.html"))
print(f"write_replay {r.steps} steps: {tw:.2f} s, {os.path.getsize('/tmp/br/bench.html')/1e6:.2f} MB")
tv,_=best(lambda: write_video(r, "/tmp/br/bench.mp4"), 1)
print(f"write_video {r.steps+1} frames: {tv:.2f} s ({(r.steps+1)/tv:.0f} frames/s), {os.path.getsize('/tmp/br/bench.mp4')/1e6:.2f} MB")
t=time.perf_counter(); r.save("/tmp/br/bench.npz"); print(f"save npz {time.perf_counter()-t:.2f} s, {os.path.getsize('/tmp/br/bench.npz')/1e6:.2f} MB")
from accd_gym.replays.replay import screenshot_replay
t=time.perf_counter(); e=screenshot_replay("/tmp/br/bench.html", "/tmp/br/bench.png"); print(f"screenshot (browser start, load, render): {time.perf_counter()-t:.1f} s errors={e}")
