"""Recorded episodes (:mod:`~accd_gym.replays.recording`, ``.npz``) and what shows them: the
self-contained 3D replay pages and MP4 videos (:mod:`~accd_gym.replays.replay`) and the headless
browser that checks and screenshots the pages (:mod:`~accd_gym.replays.browser`)."""
