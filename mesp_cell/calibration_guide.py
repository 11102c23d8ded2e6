"""The technician's side of ``mesp calibrate extrusion``: prompts, countdown, masses.

Each run: a fresh cup under the nozzle (on the scale), tared; Enter starts a countdown, the
extruder runs with a progress line, stops and settles; the net mass is read from the scale or
typed in. A typed mass outside the plausible band is refused with the reason and asked again;
a scale's is refused (``InputError``): a reading cannot be typed again. ``yes`` answers every
prompt (scripted use: masses from a scale or the emulated one).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from core.errors import InputError
from mesp_cell.scale import Scale

Check = Callable[[int, float, float], str]  # (run, seconds, grams) -> '' or why implausible


class Guide:
    """See the module docstring.

    Args:
        runs: number of runs. setpoint: mm^3/s. check: plausibility of one mass.
        expected_g: (run, seconds) -> g the current profile expects (shown at the prompt).
        scale: the balance, or None to type the masses in.
        yes: no prompts, no countdown. countdown_s: s of countdown before each run.
        ask: reads one answer (``input``). out: where the guide writes.
    """

    def __init__(self, runs: int, setpoint: float, check: Check,
                 expected_g: Callable[[int, float], float], scale: Scale | None = None,
                 yes: bool = False, countdown_s: int = 3,
                 ask: Callable[[str], str] = input, out: TextIO = sys.stdout) -> None:
        if yes and scale is None:
            raise InputError("--yes needs the masses from a scale",
                             "give --scale URL, --emulate GAIN, or --masses FILE of runs done")
        self.runs, self.setpoint, self.check = runs, setpoint, check
        self.expected_g, self.scale, self.yes = expected_g, scale, yes
        self.countdown_s, self.ask, self.out = countdown_s, ask, out
        self.tare = 0.0
        self._shown = -1.0

    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def _enter(self, text: str) -> None:
        if self.yes:
            self.say(text)
        else:
            self.ask(f"{text} [Enter] ")

    def before_run(self, i: int, seconds: float) -> None:
        """Cup, tare, countdown."""
        self.say(f"run {i + 1}/{self.runs}: {seconds:g} s at set-point {self.setpoint:g} "
                 f"mm^3/s (about {self.expected_g(i, seconds):.3f} g)")
        place = getattr(self.scale, "place_cup", None)
        if place is not None:
            place()
        self._enter("  place an empty cup on the scale under the nozzle and tare it")
        if self.scale is not None:
            self.tare = self.scale.grams()
            self.say(f"  tare {self.tare:.4f} g")
        if not self.yes and self.out.isatty():
            for k in range(self.countdown_s, 0, -1):
                print(f"\r  starting in {k} ", end="", file=self.out, flush=True)
                time.sleep(1.0)
            print("\r  extruding        ", file=self.out, flush=True)
        elif not self.yes:
            self.say(f"  starting in {self.countdown_s} s")
            time.sleep(self.countdown_s)
            self.say("  extruding")
        self._shown = -1.0

    def during_run(self, i: int, elapsed: float, seconds: float) -> None:
        """A progress line, once a second (on a terminal)."""
        if self.out.isatty() and elapsed - self._shown >= 1.0:
            self._shown = elapsed
            print(f"\r  run {i + 1}/{self.runs}: {elapsed:5.0f} / {seconds:g} s", end="",
                  file=self.out, flush=True)

    def weigh(self, i: int, seconds: float) -> float:
        """The run's net mass in g, checked."""
        end = "\r" if self.out.isatty() else ""
        print(f"{end}  run {i + 1}/{self.runs}: stopped, settled{' ' * 12}", file=self.out,
              flush=True)
        if self.scale is not None:
            grams = self.scale.grams() - self.tare
            self.say(f"  net mass {grams:.4f} g")
            why = self.check(i, seconds, grams)
            if why:
                raise InputError(why, "check the cup and the tare, then calibrate again")
            return grams
        while True:
            text = self.ask(f"  net mass of run {i + 1}, g: ").strip()
            try:
                grams = float(text)
            except ValueError:
                self.say(f"  '{text}' is not a number of grams")
                continue
            why = self.check(i, seconds, grams)
            if not why:
                return grams
            self.say(f"  refused: {why}; weigh again (tared cup?) and type the net mass")
