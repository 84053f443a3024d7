"""Numbers -> decisions -> motor: Kalman MI trend, supervisor, mill protocol, driver, emulator.

Imports nothing from ``vision``, ``sim`` or ``twin``. The pieces the application wires:

``control.trend``
    ``MITrend(config: TrendConfig | None = None)``;
    ``.update(t_s, mi, rpm) -> TrendEstimate(t_s, level, rate, level_sd, rate_sd, lo95, hi95,
    accepted, reinit, ripple, nis, rejections)``; ``config_from_window(mi) -> TrendConfig``;
    ``moving_average(x, window=150)`` (the paper's baseline).
``control.supervisor``
    ``Supervisor(config=None, predictor=None, mode=Mode.OFF)``;
    ``.step(now_s, SupervisorInputs(...)) -> Decision | None``; ``.set_mode(mode, now_s)``;
    ``.set_manual_rpm(rpm)``; ``.offer_predictions(PredictionResult)``;
    ``.prediction_request(now_s) -> PredictionRequest | None``; ``.events``.
    ``Predictor = Callable[[Sequence[float], float], Mapping[float, float]]``; wrap a slow
    one in ``AsyncPredictor(predictor)`` so ``step`` never blocks.
``control.driver``
    ``MillClient(url, *, timeout_s=0.2, retries=5, heartbeat_s=0.25, ...)``:
    ``.set_rpm(rpm)``, ``.start()``, ``.stop()``, ``.status() -> MillStatus``,
    ``.connected``, ``.last_status``, ``.close()``.
``control.emulator``
    ``MillEmulator(DeviceConfig(...), Faults(...))``: ``.open_pty() -> path``,
    ``.open_tcp(port) -> port``, ``.url``, ``.motor`` (thread-safe ``MotorState``),
    ``.disconnect()``, ``.reconnect()``, ``.close()``.
``control.trendbench``
    ``TrendSequence``, ``synthetic_sequence(seed)``, ``run_trend_bench(sequences)``.
"""
