"""Simulated plants with known truth: :mod:`.simulate` (branch, excitation, hidden effects, tracking noise),
:mod:`.beam` with :mod:`.beam_fe` (a second simulator from other physics: a finite-element
beam in wind whose effects arise from fruit mass, a gust front, two airstreams, creep and stiffening),
:mod:`.render` (a video of the simulation a tracker can follow) and :mod:`.nuisance` (what makes a real outdoor
clip harder: blur, exposure, occluders).
"""
