"""Numbers -> decisions -> motor: Kalman MI trend, supervisor, mill protocol, driver, emulator.

Imports nothing from ``vision``, ``sim`` or ``twin``. The pieces the application wires:

``control.trend``
    ``MITrend(config: TrendConfig | None = None)``;
    ``.update(t_s, mi, rpm) -> TrendEstimate(t_s, level, rate, level_sd, rate_sd, lo95, hi95,
    accepted, reinit, ripple, nis, rejections, n_since_init, meas_sd, settled)``: level in
    [0, 1], ``settled`` gates the supervisor's decisions; ``config_from_window(mi) -> TrendConfig``;
    ``MovingAverage(window=150).update(x)`` and ``moving_average(x, window=150)``: the
    paper's baseline, the project's one moving average (NaN samples skipped).
``control.supervisor``
    ``Supervisor(config=None, mode=Mode.OFF)``, pure:
    ``.step(now_s, SupervisorInputs(...), predictions=None) -> StepResult(decision, request)``
    (``request``: a ``PredictionRequest`` the application answers later with a
    ``PredictionResult`` passed to a following step); ``.set_mode(mode, now_s)``;
    ``.set_manual_rpm(rpm)``; ``.events``. ``control.supervisor_config.SupervisorConfig(limits=
    Limits(critical_rpm=...))``: its defaults are a run's; the application hands in the drum's
    critical speed (``sim.recipe.DrumSpec.critical_rpm``). In and out of a step:
    ``control.decision``; the segregation detector: ``control.segregation``.
``control.limits``
    ``Limits`` (the one set of rpm limits and what-if caps), ``simulated_rpm`` (the one cap of a
    simulated drum).
``control.driver``
    ``MillClient(url, *, timeout_s=0.2, retries=5, heartbeat_s=None, ...)``:
    ``.set_rpm(rpm)``, ``.start()``, ``.stop()``, ``.status() -> MillStatus``, ``.heartbeat()``,
    ``.connected``, ``.last_status``, ``.close()``. A NAK raises ``control.errors.MillRefused``
    (``.command``, ``.reason``: the link is fine, the command was not applied); a lost link
    ``TimeoutError``/``ConnectionError``. ``heartbeat()`` (HB) feeds the board's watchdog and is
    for the host that controls the motor; ``status()`` (STA) is for everybody else. Each client
    starts its sequence numbers at a random value.
``control.emulator``
    ``MillEmulator(DeviceConfig(...), Faults(...))``: ``.open_pty() -> path``,
    ``.open_tcp(port) -> port``, ``.url``, ``.motor`` (thread-safe ``MotorState``),
    ``.disconnect()``, ``.reconnect()``, ``.close()``.
``control.trendbench``
    ``TrendSequence``, ``synthetic_sequence(seed)``, ``real_sequences(RealFrameMI, seed)``
    (sequences of real frames' MI, measured by the application), ``run_trend_bench(sequences)``.
"""
