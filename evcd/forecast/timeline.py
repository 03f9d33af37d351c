"""The number of vehicles at each station over time, read from the stations' visit records.

A vehicle is *at* a station (charging or waiting) from its record's ``arrival_time`` (inclusive) to its
``release_time`` (exclusive), as :meth:`ChargingController.occupancy
<evcd.sim.charging.ChargingController.occupancy>` counts it after a step; it charges from its
``start_time`` (when it got a point; a record without one never charged). A timeline is built from the
records read at one moment, ``known_until``: what happens after it is unknown, a visit still going on
then (``release_time`` ``None`` or later) counts until ``known_until``, and a question about a later
time is refused unless asked with ``clip=True``.

    timeline = OccupancyTimeline.from_records(controller.records, ["cs1", "cs2"], known_until=now)
    timeline.at(now)                  # array([3, 1]): vehicles at cs1 and cs2 now
    timeline.at([0.0, 600.0, now])    # shape (3, 2)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from evcd.utils.validation import check_real, require

if TYPE_CHECKING:
    from evcd.sim.charge_record import ChargeRecord


def _visit(record: ChargeRecord | Mapping[str, Any]) -> tuple[str, float, float | None, float | None]:
    """``(station, arrival_time, release_time, start_time)`` of a record or of its ``to_dict()`` form
    (``start_time`` may be absent from a mapping: the visit never charged)."""
    if isinstance(record, Mapping):
        missing = [k for k in ("station", "arrival_time", "release_time") if k not in record]
        require(
            not missing,
            f"record {dict(record)!r} lacks {missing}: a record needs station, "
            "arrival_time and release_time (ChargeRecord.to_dict() has them)",
        )
        station, arrival, release = record["station"], record["arrival_time"], record["release_time"]
        start = record.get("start_time")
    else:
        station, arrival, release = record.station, record.arrival_time, record.release_time
        start = record.start_time
    arrival = check_real("arrival_time", arrival)
    if release is not None:
        release = check_real("release_time", release)
        require(
            release >= arrival,
            f"release_time={release} of a visit at {station!r}: must be >= its arrival_time={arrival}",
        )
    if start is not None:
        start = check_real("start_time", start)
        require(
            arrival <= start and (release is None or start <= release),
            f"start_time={start} of a visit at {station!r}: must lie between its arrival_time={arrival} "
            f"and its release_time={release}",
        )
    return str(station), arrival, release, start


class OccupancyTimeline:
    """Vehicles at each of ``stations`` (charging + waiting) as a step function of time.

    Build it with :meth:`from_records`. Per station it keeps the sorted arrival times and the sorted
    release times (those up to ``known_until``); the count at ``t`` is the arrivals at or before ``t``
    less the releases at or before ``t`` (two binary searches per station). It also keeps the charging
    sessions, ``(start, end)`` pairs (``end`` infinite while unknown), for :meth:`charging_since` and
    :meth:`charge_durations`.

    Attributes:
        stations: the station ids, in the order of the columns of :meth:`at`.
        known_until: the time the records were read; the timeline says nothing about later times.
    """

    def __init__(
        self,
        stations: Sequence[str],
        arrivals: Sequence[np.ndarray],
        releases: Sequence[np.ndarray],
        known_until: float,
        sessions: Sequence[np.ndarray] | None = None,
    ) -> None:
        """Prefer :meth:`from_records`. ``arrivals[j]`` and ``releases[j]`` are the sorted arrival and
        release times at ``stations[j]`` (each release belongs to an arrival; all <= ``known_until``);
        ``sessions[j]`` the ``(start, end)`` rows of its charging sessions sorted by start (``end``
        ``inf`` while unknown; none by default)."""
        self.stations: tuple[str, ...] = tuple(stations)
        self.known_until: float = check_real("known_until", known_until)
        require(len(self.stations) > 0, "stations=(): a timeline needs at least one station")
        require(
            len(set(self.stations)) == len(self.stations),
            f"stations={list(self.stations)}: the station ids must be distinct",
        )
        require(
            len(arrivals) == len(releases) == len(self.stations),
            f"{len(arrivals)} arrival and {len(releases)} release arrays for {len(self.stations)} "
            "stations: need one of each per station",
        )
        self._arrivals = [np.asarray(a, dtype=np.float64) for a in arrivals]
        self._releases = [np.asarray(r, dtype=np.float64) for r in releases]
        if sessions is None:
            sessions = [np.empty((0, 2)) for _ in self.stations]
        require(
            len(sessions) == len(self.stations),
            f"{len(sessions)} session arrays for {len(self.stations)} stations: need one per station",
        )
        self._sessions = [np.asarray(x, dtype=np.float64).reshape(-1, 2) for x in sessions]

    @classmethod
    def from_records(
        cls,
        records: Iterable[ChargeRecord | Mapping[str, Any]],
        stations: Sequence[str],
        known_until: float,
    ) -> OccupancyTimeline:
        """The timeline of the visits in ``records`` (``ChargeRecord`` objects or their ``to_dict()``
        form, e.g. a controller's ``state_dict()["records"]``), read at time ``known_until``.

        Records arriving after ``known_until`` are ignored; a visit with ``release_time`` ``None`` or
        after ``known_until`` counts as present until ``known_until``; a charging session started
        after ``known_until`` is not known yet.

        Raises:
            ValueError: a record at a station not in ``stations`` (naming it and the allowed ones), a
                record without the fields needed or with a release before its arrival, repeated or no
                station ids, a ``known_until`` that is not a finite number.
        """
        known_until = check_real("known_until", known_until)
        stations = tuple(stations)
        column = {sid: j for j, sid in enumerate(stations)}
        arrivals: list[list[float]] = [[] for _ in stations]
        releases: list[list[float]] = [[] for _ in stations]
        sessions: list[list[tuple[float, float]]] = [[] for _ in stations]
        for record in records:
            station, arrival, release, start = _visit(record)
            if station not in column:
                raise ValueError(
                    f"a record at station {station!r}: the timeline's stations are {list(stations)}"
                )
            if arrival > known_until:
                continue
            j = column[station]
            arrivals[j].append(arrival)
            known_release = release is not None and release <= known_until
            if known_release:
                releases[j].append(release)
            if start is not None and start <= known_until:
                sessions[j].append((start, release if known_release else np.inf))
        return cls(
            stations,
            [np.sort(a) for a in arrivals],
            [np.sort(r) for r in releases],
            known_until,
            [np.array(sorted(x), dtype=np.float64).reshape(-1, 2) for x in sessions],
        )

    def _times(self, times: Any, clip: bool) -> np.ndarray:
        """``times`` as finite float64, clipped to ``known_until`` or refused beyond it."""
        t = np.asarray(times, dtype=np.float64)
        require(bool(np.isfinite(t).all()), f"times={times!r}: must be finite numbers")
        if clip:
            return np.minimum(t, self.known_until)
        if t.size and (late := float(t.max())) > self.known_until:
            raise ValueError(
                f"time {late:g} is after known_until={self.known_until:g}: the future is unknown; "
                "ask for times <= known_until, or pass clip=True for the value at known_until"
            )
        return t

    def _count(self, j: int, t: np.ndarray) -> np.ndarray:
        """Vehicles at station ``j`` at each of ``t`` (any shape)."""
        here = np.searchsorted(self._arrivals[j], t, side="right")
        gone = np.searchsorted(self._releases[j], t, side="right")
        return (here - gone).astype(np.int64)

    def at(self, times: float | Sequence[float] | np.ndarray, clip: bool = False) -> np.ndarray:
        """Vehicles at every station at ``times``.

        Args:
            times: one time, or a 1-D array of them (seconds of the day).
            clip: evaluate times after ``known_until`` at ``known_until`` instead of refusing them.

        Returns:
            int64 counts, shape ``(len(times), m)`` (``(m,)`` for one time), columns in ``stations``
            order.

        Raises:
            ValueError: a time after ``known_until`` (unless ``clip``), a time that is not finite, or
                times of more than one dimension.
        """
        t = self._times(times, clip)
        require(
            t.ndim <= 1,
            f"times of shape {t.shape}: must be one time or a 1-D array of times "
            "(at_each takes one time per station)",
        )
        flat = np.atleast_1d(t)
        out = np.empty((flat.size, len(self.stations)), dtype=np.int64)
        for j in range(len(self.stations)):
            out[:, j] = self._count(j, flat)
        return out[0] if t.ndim == 0 else out

    def at_each(self, times: Sequence[float] | np.ndarray, clip: bool = False) -> np.ndarray:
        """Vehicles at station ``j`` at ``times[..., j]``: one time per station (e.g. the arrival time of
        an EV at each station), shape ``(m,)`` or a batch ``(k, m)``; returns int64 of the same shape.

        Raises:
            ValueError: the last dimension is not the number of stations, or as :meth:`at`.
        """
        t = self._times(times, clip)
        m = len(self.stations)
        require(
            t.ndim >= 1 and t.shape[-1] == m,
            f"times of shape {t.shape}: must end in the number of stations ({m})",
        )
        out = np.empty(t.shape, dtype=np.int64)
        for j in range(m):
            out[..., j] = self._count(j, t[..., j])
        return out

    def truncated(self, known_until: float) -> OccupancyTimeline:
        """This timeline as it was known at the earlier time ``known_until``: the same counts up to it,
        and later times refused (what a forecaster deciding then may read).

        Raises:
            ValueError: ``known_until`` after this timeline's own, or not a finite number.
        """
        t = check_real("known_until", known_until, high=self.known_until)
        arrivals = [a[: np.searchsorted(a, t, side="right")] for a in self._arrivals]
        releases = [r[: np.searchsorted(r, t, side="right")] for r in self._releases]
        sessions = []
        for x in self._sessions:
            x = x[x[:, 0] <= t].copy()
            x[x[:, 1] > t, 1] = np.inf
            sessions.append(x)
        return OccupancyTimeline(self.stations, arrivals, releases, t, sessions)

    def arrival_times(self) -> tuple[np.ndarray, ...]:
        """Per station, the sorted arrival times of its visits up to ``known_until`` (copies)."""
        return tuple(a.copy() for a in self._arrivals)

    def charging_since(self, now: float) -> tuple[np.ndarray, ...]:
        """Per station, the start times of the sessions charging at ``now`` (started at or before it,
        not yet ended), sorted.

        Raises:
            ValueError: ``now`` after ``known_until`` or not a finite number.
        """
        now = check_real("now", now, high=self.known_until)
        return tuple(x[(x[:, 0] <= now) & (x[:, 1] > now), 0] for x in self._sessions)

    def charge_durations(self) -> np.ndarray:
        """The durations (end - start) of every session that ended by ``known_until``, all stations."""
        done = [x[np.isfinite(x[:, 1])] for x in self._sessions]
        return np.concatenate([x[:, 1] - x[:, 0] for x in done]) if done else np.empty(0)

    def __repr__(self) -> str:
        visits = sum(a.size for a in self._arrivals)
        return (
            f"OccupancyTimeline(stations={list(self.stations)}, visits={visits}, "
            f"known_until={self.known_until:g})"
        )
