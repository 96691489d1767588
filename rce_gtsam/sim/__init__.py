"""Simulated plants with known truth: :mod:`.simulate` (branch, excitation, hidden effects, tracking noise),
:mod:`.render` (a video of the simulation a tracker can follow) and :mod:`.nuisance` (what makes a real outdoor
clip harder: blur, exposure, occluders).
"""
