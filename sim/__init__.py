"""Physics -> frames: the 2D soft-sphere DEM drum twin, renderer, calibration, what-if studies.

Imports ``vision`` (to measure its own frames) and nothing else of drumtwin.

- ``sim.recipe``: ``DrumSpec``, ``ParticleSpec``, ``Recipe``, ``PAPER_RECIPE``, ``slice_2d``
- ``sim.params``: ``SimParams``, the paper materials as defaults, ``check_rpm``; ``sim.twin_base``:
  ``Particles``, ``ContactStats``, ``FixedStepTwin`` (one fixed internal step)
- ``sim.drum``: ``DrumSim`` (advance/step/set_rpm/particles/snapshot/restore/stats), ``SimState``
- ``sim.dem``: the compiled DEM step loop (spring-dashpot contacts, Coulomb sliding, rolling friction,
  the drum circle as the wall, overlap statistics); ``sim.dem_contact`` its contact constants,
  ``sim.dem_neighbours`` its Verlet neighbour list
- ``sim.pymunk_twin``: ``PymunkDrumSim`` (any shape, baffles); ``sim.pymunk_shapes``,
  ``sim.pymunk_drum``, ``sim.pymunk_contacts`` its particles, drum and contacts
- ``sim.render``: ``Renderer``, ``Realism`` (synthetic camera)
- ``sim.measure``: ``particle_mi``, ``free_surface`` / ``particle_slope_deg`` (free surface),
  ``particle_axis_deg`` (principal axis), ``twin_meter``
- ``sim.calibrate``: ``calibrate`` -> ``Calibration`` (sliding + rolling friction, reachable range)
- ``sim.whatif``: ``WhatIfJob``, ``run_study``, ``summarize``, ``flow_regime``, ``froude``
- ``sim.errors``: ``SimError``, ``check_number``, ``check_seed``
- ``sim.validation``: regenerates docs/validation.md's numbers and plots
"""
