"""Commissioning a rig in one step (issue 39): from a rig's frames to a calibrated twin checked against
the camera, ``mixer.toml`` and a self-contained report (``drumtwin commission``, the dashboard's set-up
view). ``steps`` runs the steps, ``checks`` holds every check and its tolerance (pure), ``measure`` the
per-frame numbers both the camera and the twin are held to, ``twin_check`` the twin's runs,
``report``/``figures`` the HTML, ``output`` the files, ``source`` the frames, ``rigs`` rendered rigs of
known answer (tests, benchmark). See docs/commissioning.md."""
