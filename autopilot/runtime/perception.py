"""Perception lanes: what the running step sees. Its pipelines, grouped by camera into lanes
(a detection task and an estimation task per camera in use), the tracks they keep, and the
extra sensor streams (UWB, the rover's reports) the pipelines that take them are fed. Each
frame a lane receives is then shown to the watch's watchers (:mod:`autopilot.runtime.watch`)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING

import numpy as np

from autopilot.behaviors.base import Percept
from autopilot.config import AppConfig
from autopilot.flightlog import records as ch
from autopilot.pipeline import KeepsRecords, Pipeline, PipelineSpec, SensorFed, make_pipeline
from autopilot.runtime.flight import Flight, Lane, ProcessedFrame, Track
from drivers.base import Frame, VehicleState
from drivers.capabilities import SENSOR_STREAMS
from drivers.stages import STAGES
from drivers.threads import lower_this_thread

if TYPE_CHECKING:
    from autopilot.runtime.governor import LoadGovernor
    from autopilot.runtime.watch import Watch

log = logging.getLogger(__name__)



def detection_charge(config: AppConfig, kinds: Sequence[str]
                     ) -> float | Callable[[list[tuple[object | None, float, str | None]]], float]:
    """What the lockstep clock charges for detecting ``kinds`` in one frame (``sim.compute_*``):
    a fixed time, each kind's modelled cost, or (``measured``) a function of
    :func:`detect_all`'s results, the time they really took; all but ``fixed`` scaled by
    ``sim.compute_scale`` (a slower companion computer)."""
    sim, fixed_s = config.sim, config.runtime.lockstep_detection_s
    if sim.compute_charge == "fixed":
        return fixed_s * len(kinds)
    scale = sim.compute_scale
    if sim.compute_charge == "measured":
        return lambda results: scale * sum(ms for _, ms, _ in results) / 1e3
    return scale * sum(sim.compute_cost_ms[k] / 1e3 if k in sim.compute_cost_ms else fixed_s
                       for k in kinds)


def detect_all(pipelines: list[Pipeline], frame: Frame, hints: list[object | None]
               ) -> list[tuple[object | None, float, str | None]]:
    """Each pipeline's detection in one frame, with its processing time (ms) and, when its
    detector raised, what it raised (no detection then: the flight goes on without it)."""
    out = []
    for pipeline, hint in zip(pipelines, hints, strict=True):
        started = time.perf_counter()
        error = None
        try:
            with STAGES.stage(f"detection.{pipeline.name}"):
                det = pipeline.detect(frame.image, frame.camera, frame.time_s, hint)
        except Exception as exc:
            log.exception("the %s detector raised on frame %d", pipeline.name, frame.seq)
            det, error = None, f"{type(exc).__name__}: {exc}"
        out.append((det, (time.perf_counter() - started) * 1e3, error))
    return out


class PerceptionLanes:
    """A pipeline lives for the whole run (a target tracked in one step is still tracked when
    a later step uses the same pipeline); only the lanes the running step uses run."""

    def __init__(self, flight: Flight, specs: Iterable[PipelineSpec],
                 fail_step: Callable[[str], None], watch: Watch | None = None) -> None:
        self.flight = flight
        #: the watchers that look at every frame a lane receives, after its pipelines
        self.watch = watch
        self.pipelines: dict[str, Pipeline] = {}
        self.tracks: dict[str, Track] = {}
        self.group: asyncio.TaskGroup | None = None  # (the run's, while it runs)
        self.late_tasks: list[asyncio.Task] = []  # sensor streams a goal's pipeline started
        self._sensors_started = False
        self.add(specs)
        self.fail_step = fail_step  # a detector or estimator raised: the step cannot go on
        self.active: tuple[str, ...] = ()  # the running step's pipelines (keys)
        self.lanes: dict[str, Lane] = {}
        self.latest_processed: dict[str, ProcessedFrame] = {}
        self._processed_signals: dict[str, asyncio.Event] = {}
        self.governor: LoadGovernor | None = None  # (real time: frames skipped when late)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="detect",
                                        initializer=lower_this_thread)

    def add(self, specs: Iterable[PipelineSpec]) -> None:
        """Pipelines a step (or a goal) brings, made once each."""
        for spec in specs:
            if spec.key not in self.pipelines:
                self.pipelines[spec.key] = make_pipeline(self.flight.config, spec)
                self.tracks[spec.key] = Track(self.pipelines[spec.key])
        if self.group is not None:  # a goal's pipeline may take sensors
            self.late_tasks += self.sensor_tasks(self.group)

    def close(self) -> None:
        STAGES.sample_threads()  # (the pool's thread takes its CPU time with it)
        self._pool.shutdown(wait=True, cancel_futures=True)

    # -- what the behaviours and the console read ------------------------------------------

    def percepts(self, now: float) -> tuple[Percept, ...]:
        """The running step's percepts (in its pipelines' order)."""
        out = []
        for key in self.active:
            track = self.tracks[key]
            p = track.pipeline
            out.append(Percept(p.name, p.kind, track.detection, track.last_detection,
                               track.frame_seq, p.target(now)))
        return tuple(out)

    def first_track(self) -> Track | None:
        """The running step's first pipeline's track (the one shown)."""
        return self.tracks[self.active[0]] if self.active else None

    def add_state(self, state: VehicleState) -> None:
        with STAGES.stage("estimation"):
            for pipeline in self.pipelines.values():
                pipeline.add_state(state)
                self.log_relative(pipeline)

    def overlay(self, camera: str, frame: Frame, now: float) -> tuple[dict | None, dict | None]:
        """The detection record of ``frame`` when the running step's pipeline on ``camera``
        processed it, and that pipeline's target estimate now (the console's overlays)."""
        det = est = None
        processed = self.latest_processed.get(camera)
        for key in self.active:
            track = self.tracks[key]
            if track.pipeline.camera != camera:
                continue
            if processed is not None and processed.seq == frame.seq:
                i = self.lanes[camera].keys.index(key) if camera in self.lanes and \
                    key in self.lanes[camera].keys else -1
                if i >= 0:
                    det = track.pipeline.detection_record(
                        frame.seq, frame.time_s, camera, processed.detections[i],
                        processed.hints[i] if i < len(processed.hints) else None)
            target = track.pipeline.target(now)
            if target is not None:
                cov = np.asarray(target.covariance)
                est = {"time_s": now, "position_ned_m": target.position_ned_m.tolist(),
                       "velocity_ned_m_s": target.velocity_ned_m_s.tolist(),
                       "position_cov_m2": cov[:3, :3].reshape(-1).tolist(),
                       "velocity_std_m_s": np.sqrt(np.clip(np.diag(cov)[3:6], 0, None)
                                                   ).tolist()}
            break
        return det, est

    async def processed_frame(self, camera: str, seq: int, timeout_s: float
                              ) -> ProcessedFrame | None:
        """The running step's pipelines' result for frame ``seq`` of ``camera``, waiting up to
        ``timeout_s`` for it (None: no pipeline reads that camera now, or it did not come)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while camera in self.lanes:
            found = self.latest_processed.get(camera)
            if found is not None and found.seq >= seq:
                return found if found.seq == seq else None
            signal = self._processed_signals.setdefault(camera, asyncio.Event())
            try:
                await asyncio.wait_for(signal.wait(), deadline - loop.time())
            except TimeoutError:
                return None
        return None

    # -- the lanes -------------------------------------------------------------------------

    def use(self, keys: tuple[str, ...]) -> None:
        """Run exactly ``keys``' pipelines: one lane per camera; lanes whose pipelines do not
        change keep running (their subscriptions and slots are not disturbed)."""
        self.active = keys
        wanted: dict[str, tuple[str, ...]] = {}
        for key in keys:
            camera = self.pipelines[key].camera
            if not camera:
                continue  # it reads no camera (a deck tracked without its tag)
            wanted[camera] = (*wanted.get(camera, ()), key)
        for camera, lane in list(self.lanes.items()):
            if wanted.get(camera) != lane.keys:
                for task in lane.tasks:
                    task.cancel()
                del self.lanes[camera]
        if self.group is None:
            return
        for camera, lane_keys in wanted.items():
            if camera in self.lanes:
                continue
            lane = Lane(camera, lane_keys)
            lane.tasks = [
                self.group.create_task(self._detection(lane), name=f"detection-{camera}"),
                self.group.create_task(self._estimation(lane), name=f"estimation-{camera}")]
            self.lanes[camera] = lane

    async def _detection(self, lane: Lane) -> None:
        f = self.flight
        pipelines = [self.pipelines[key] for key in lane.keys]
        budget = detection_charge(f.config, [p.kind for p in pipelines])
        async with contextlib.aclosing(f.vehicle.frames(lane.camera)) as frames:
            async for frame in frames:
                if self.governor is not None and not self.governor.take(lane.camera):
                    continue
                received = f.clock.now()
                hints = [p.hint(frame.time_s, frame.camera) for p in pipelines]
                results = await f.clock.run_blocking(
                    detect_all, pipelines, frame, hints, executor=self._pool, budget_s=budget)
                processed = ProcessedFrame(frame.time_s, frame.seq, frame,
                                           tuple(det for det, _, _ in results), tuple(hints))
                lane.frames.put(processed)
                self.latest_processed[lane.camera] = processed
                signal = self._processed_signals.pop(lane.camera, None)
                if signal is not None:  # (whoever waits for this camera's next one)
                    signal.set()
                detected = f.clock.now()
                for pipeline, hint, (det, elapsed_ms, error) in zip(pipelines, hints, results,
                                                                    strict=True):
                    if error is not None:
                        self.fail_step(f"the {pipeline.name} detector raised {error}")
                    f.stats.frames += 1
                    f.stats.detections += det is not None
                    record = pipeline.detection_record(frame.seq, frame.time_s,
                                                       frame.camera.name, det, hint)
                    record.update(processing_ms=elapsed_ms, received_s=received,
                                  detected_s=detected)
                    f.log.write(ch.detection_topic(pipeline.name), frame.time_s, record)
                if self.watch is not None:  # (the step's estimate is on its way already)
                    await self.watch.look(frame, self._pool)

    async def _estimation(self, lane: Lane) -> None:
        while True:
            item = await lane.frames.get()
            for key, det in zip(lane.keys, item.detections, strict=True):
                track = self.tracks[key]
                track.detection = det
                track.frame_seq = item.seq
                track.frames += 1
                if det is not None:
                    track.detections += 1
                    track.last_detection = det
                    try:
                        with STAGES.stage("estimation"):
                            record = track.pipeline.estimate(item.time_s, item.frame.camera,
                                                             det)
                    except Exception as exc:  # the step cannot fly on it: it fails
                        log.exception("the %s estimator raised", track.pipeline.name)
                        self.fail_step(f"the {track.pipeline.name} estimator raised "
                                       f"{type(exc).__name__}: {exc}")
                        continue
                    if record is not None:
                        self.flight.log.write(ch.TARGET_ESTIMATES, item.time_s, record)
                    self.log_relative(track.pipeline)
            self.flight.wake.put(item.time_s)

    # -- the extra sensor streams ----------------------------------------------------------

    def sensor_tasks(self, tasks: asyncio.TaskGroup) -> list[asyncio.Task]:
        """The vehicle's extra sensor streams (UWB, the rover's reports) while any pipeline
        takes them: logged, and handed to those pipelines as they arrive."""
        if self._sensors_started or not any(isinstance(p, SensorFed)
                                            for p in self.pipelines.values()):
            return []
        self._sensors_started = True
        vehicle = self.flight.vehicle
        found = []
        for name in sorted(vehicle.sensors):
            capability, stream = SENSOR_STREAMS.get(name, (None, None))
            if capability is not None and isinstance(vehicle, capability):
                found.append(tasks.create_task(self._sensor(stream(vehicle),
                                                            ch.sensor_topic(name)),
                                               name=f"sensor-{name}"))
        return found

    async def _sensor(self, subscribe, topic: str) -> None:
        f = self.flight
        async with contextlib.aclosing(subscribe(buffer=64)) as samples:
            async for sample in samples:
                record = ch.clean(dataclasses.asdict(sample))
                record["received_s"] = f.clock.now()
                f.log.write(topic, sample.time_s, record)
                for pipeline in self.pipelines.values():
                    if isinstance(pipeline, SensorFed):
                        pipeline.add_sensor(sample)
                        self.log_relative(pipeline)

    def log_relative(self, pipeline: Pipeline) -> None:
        if not isinstance(pipeline, KeepsRecords):
            return
        for record in pipeline.take_records():
            self.flight.log.write(ch.RELATIVE_ESTIMATES, record["time_s"], record)
