"""``drumtwin run``: one live run, from its settings to its threads, one concern per module.

* ``twin.run.main``: the entry point, ``run_live(cfg, seams, *, wait, on_dashboard)`` (demo and
  hardware alike; the CLI calls it), the demo's ``DemoStart``, ``open_mill``.
* ``twin.run.settings``: a run's settings and their layering (``supervisor_config``,
  ``trend_config``, ``endpoint_config``, ``resolve_inputs`` for the config file) and the typed
  test ``Seams``.
* ``twin.run.loop``: ``LiveLoop``, the run's threads and their lifecycle (the composition root
  of the workers in ``twin.live``: the only place their threads start and are joined), its
  failure policy.
* ``twin.run.operator``: ``Operator``, the operator's commands (the dashboard's ``Controls``).
* ``twin.run.metadata``: ``versions()``, ``mixer_metadata()`` (what a run records about itself).
"""
