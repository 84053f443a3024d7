"""Physics -> frames: the 2D pymunk drum twin, renderer, calibration, what-if studies.

Imports ``vision`` (to measure its own frames) and nothing else of drumtwin.

- ``sim.recipe``: ``DrumSpec``, ``ParticleSpec``, ``Recipe``, ``PAPER_RECIPE``, ``slice_2d``
- ``sim.drum``: ``DrumSim`` (step/advance/set_rpm/particles/snapshot/restore), ``SimState``
- ``sim.render``: ``Renderer``, ``Realism`` (synthetic camera)
- ``sim.measure``: ``particle_mi``, ``particle_slope_deg``, ``twin_meter``
- ``sim.calibrate``: ``calibrate`` -> ``Calibration``
- ``sim.whatif``: ``WhatIfJob``, ``run_study``, ``summarize``, ``regime``
- ``sim.validation``: regenerates docs/validation.md's plots
"""
