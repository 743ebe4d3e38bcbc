"""What a method claims and what every aligner refuses: the bases, latitudes, gyro grades and aiding a method
claims (:class:`Supports`, which the conformance matrix runs), and the checks that refuse an IMU whose gyro bias
hides the earth rate or a base that accelerates without aiding (one line each, naming the method)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.simulation import earth, units


#: Largest gyro bias, as a fraction of the horizontal earth rate, with which the azimuth counts as observable:
#: a bias b turns the gyrocompass's north by up to asin(b / (OMEGA_IE cos L)), 30 deg at this ratio.
MAX_BIAS_TO_EARTH_RATE = 0.5


def gyro_bias(spec) -> float:
    """The gyro bias an aligner does not know, rad/s: the largest axis of ``sqrt(bias^2 + bias_sigma^2 +
    instability^2)`` of ``spec.gyro`` (fixed, per-run random and drifting parts)."""
    return float(np.max(spec.gyro.unknown_bias()))


def azimuth_bias_ratio(spec, lat) -> float:
    """Gyro bias over the horizontal earth rate: how far the IMU's gyros can turn a gyrocompass's north.

    The bias is :func:`gyro_bias` (none of its parts is known to the aligner), rad/s; the horizontal earth rate
    is ``OMEGA_IE cos(lat)`` (``lat`` rad). sin of the azimuth error the bias causes is this ratio.
    """
    b = gyro_bias(spec)
    w_h = earth.OMEGA_IE * abs(np.cos(lat))
    return np.inf if w_h == 0 else b / w_h


def check_azimuth_observable(spec, site, name: str):
    """Raise ValueError (one line) when the IMU's gyro bias hides the earth rate at the site.

    A method given an IMU model refuses rather than returning a confident heading that the bias decides
    (:data:`MAX_BIAS_TO_EARTH_RATE`; a MEMS gyro of 10 deg/h against 12.5 deg/h of horizontal earth rate at
    34 deg). ``spec`` None (no model given) is not checked.
    """
    if spec is None:
        return
    ratio = azimuth_bias_ratio(spec, site.lat)
    if ratio > MAX_BIAS_TO_EARTH_RATE:
        b = gyro_bias(spec)
        w_h = earth.OMEGA_IE * abs(np.cos(site.lat))
        raise ValueError(f"{name}: the azimuth is unobservable with IMU '{spec.name}': gyro bias {b / units.DEG_PER_H:.3g} "
                         f"deg/h against a horizontal earth rate of {w_h / units.DEG_PER_H:.3g} deg/h at "
                         f"{np.degrees(site.lat):.1f} deg latitude (more than {MAX_BIAS_TO_EARTH_RATE:g} of it: the "
                         f"heading could be {np.degrees(np.arcsin(min(ratio, 1.0))):.0f} deg or more off)")


def check_not_accelerating(excess, limit, name: str):
    """Raise ValueError (one line) when a recording's mean specific force differs from gravity by more than
    ``limit`` (both in g): a base without a velocity reference must be stationary or swaying, and a constant
    horizontal acceleration ``a`` raises the mean specific force by about ``a^2 / 2 g^2`` (read as a tilt of
    ``a / g`` otherwise).

    ``excess`` (R,) is ``|mean specific force| / g - 1`` per recording; ``name`` opens the message.
    """
    excess = np.asarray(excess, dtype=float)
    r = int(np.argmax(np.abs(excess)))
    if abs(excess[r]) > limit:
        raise ValueError(f"{name}: the base accelerates (recording {r}: the specific force differs from gravity by "
                         f"{excess[r] * 1e3:+.1f} mg, on a stationary or swaying base by less than {limit * 1e3:.1f} mg: "
                         f"about {np.sqrt(2 * abs(excess[r])):.2f} g of horizontal acceleration): a moving base needs its "
                         f"velocity or position as aiding (--aiding FILE)")


#: Kinds of base a method can claim: stationary, swaying/moored (no translation beyond a disturbance), and
#: moving (translating, with a velocity reference).
BASE_KINDS = ("static", "sway", "moving")


@dataclass(frozen=True)
class Supports:
    """The conditions a method claims to align under; the conformance matrix runs it on these and only these.

    Parameters
    ----------
    bases : tuple of str
        Kinds of base (:data:`BASE_KINDS`); "moving" means a translating base with a velocity reference
        (``vref``). Empty: no condition is claimed (a paper's printed parameters, kept to reproduce it).
    max_abs_lat_deg : float
        Highest abs(latitude) claimed, deg (gyrocompassing loses the horizontal earth rate toward the poles).
    needs_init : bool
        The method cannot start on its own: it needs an initial attitude (a navigator, not an aligner).
    max_bias_ratio : float
        Largest gyro bias claimed, as a fraction of the horizontal earth rate at the site
        (:func:`azimuth_bias_ratio`, dimensionless; the azimuth limit is about its arcsine). The default is
        the refusal level :data:`MAX_BIAS_TO_EARTH_RATE`; 0.05 claims navigation-grade gyros only (a
        0.01 deg/h gyro is 0.0004-0.0014 up to 75 deg, a 1 deg/h tactical one 0.07-0.29).
    aiding : tuple of str
        On a moving base, the aiding claimed: ``"velocity"`` rows, ``"position"`` rows (alone; with both, either
        claim covers the condition).
    min_aiding_hz : float
        On a moving base, the slowest rate of aiding rows claimed, Hz.
    max_outage_s : float
        On a moving base, the longest gap in the aiding claimed, s.
    max_bias_ratio_moving : float, optional
        On a moving base, the largest gyro bias claimed (as ``max_bias_ratio``); None: ``max_bias_ratio``. A turn
        makes the gyro bias partly observable, so a method without a bias model may hold on a fixed base what it
        does not in motion.
    """

    bases: tuple = ("static", "sway")
    max_abs_lat_deg: float = 80.0
    needs_init: bool = False
    max_bias_ratio: float = MAX_BIAS_TO_EARTH_RATE
    aiding: tuple = ("velocity", "position")
    min_aiding_hz: float = 0.0
    max_outage_s: float = float("inf")
    max_bias_ratio_moving: float | None = None

    def __post_init__(self):
        bad = [b for b in self.bases if b not in BASE_KINDS]
        if bad:
            raise ValueError(f"supports bases: expected some of {BASE_KINDS}, found {bad}")
        if not 0.0 <= self.max_abs_lat_deg <= 90.0:
            raise ValueError(f"supports max_abs_lat_deg: expected 0 to 90 deg, found {self.max_abs_lat_deg}")
        bad = [k for k in self.aiding if k not in ("velocity", "position")]
        if bad:
            raise ValueError(f"supports aiding: expected some of ('velocity', 'position'), found {bad}")
        if not 0.0 < self.max_bias_ratio <= MAX_BIAS_TO_EARTH_RATE:
            raise ValueError(f"supports max_bias_ratio: expected a fraction of the horizontal earth rate in (0, "
                             f"{MAX_BIAS_TO_EARTH_RATE:g}], found {self.max_bias_ratio}")

    def covers(self, base: str, lat_deg: float, bias_ratio: float = 0.0, aiding=(), aiding_hz=float("inf"),
               outage_s=0.0) -> bool:
        """Whether the method claims a condition with this base, at this latitude (deg), with a gyro whose bias is
        ``bias_ratio`` of the horizontal earth rate there (:func:`azimuth_bias_ratio`) and, on a moving base, the
        aiding kinds ``aiding`` (``"velocity"``, ``"position"``) at ``aiding_hz`` with gaps up to ``outage_s`` s:
        :meth:`unclaimed` finds nothing."""
        return not self.unclaimed(base, lat_deg, bias_ratio, aiding, aiding_hz, outage_s)

    def unclaimed(self, base: str, lat_deg: float, bias_ratio: float | None = 0.0, aiding=(),
                  aiding_hz=float("inf"), outage_s=0.0, gyro="the gyro") -> list:
        """What of a condition the method does not claim, one short reason each (empty: it claims it all).

        Parameters
        ----------
        base : str
            The kind of base (:data:`BASE_KINDS`).
        lat_deg : float
            Latitude, deg.
        bias_ratio : float or None
            The gyro bias over the horizontal earth rate there (:func:`azimuth_bias_ratio`, dimensionless); None:
            not known (not checked).
        aiding : tuple of str
            On a moving base, the kinds of aiding rows given (``"velocity"``, ``"position"``); empty: not checked.
        aiding_hz : float
            Their rate, Hz.
        outage_s : float
            Their longest gap beyond the rows' interval, s.
        gyro : str
            What the bias reason calls the gyro (e.g. the IMU's name and bias).
        """
        if not self.bases:
            return ["it claims no condition: " + ("a navigator, it needs an initial attitude" if self.needs_init else
                                                  "its parameters are kept to reproduce a paper")]
        out = []
        if base not in self.bases:
            out.append(f"a {BASE_WORDS.get(base, base)} base, which it does not claim (it claims "
                       f"{', '.join(self.bases)})")
        if abs(lat_deg) > self.max_abs_lat_deg + 1e-9:
            out.append(f"latitude {lat_deg:.4g} deg, beyond the {self.max_abs_lat_deg:g} deg it claims")
        moving = base == "moving"
        most = self.max_bias_ratio if not moving or self.max_bias_ratio_moving is None else self.max_bias_ratio_moving
        if bias_ratio is not None and bias_ratio > most + 1e-12:
            out.append(f"{gyro} is {bias_ratio:.3g} of the horizontal earth rate at the site, beyond the {most:g} it "
                       f"claims" + (" on a moving base" if moving and self.max_bias_ratio_moving is not None else ""))
        if moving and aiding:
            if not any(k in self.aiding for k in aiding):
                out.append(f"aiding of {' and '.join(aiding)} rows, which it does not claim (it claims "
                           f"{' or '.join(self.aiding)})")
            if aiding_hz < self.min_aiding_hz - 1e-9:
                out.append(f"aiding rows at {aiding_hz:.3g} Hz, below the {self.min_aiding_hz:g} Hz it claims")
            if outage_s > self.max_outage_s + 1e-9:
                out.append(f"an aiding outage of {outage_s:.3g} s, beyond the {self.max_outage_s:g} s it claims")
        return out


#: How :meth:`Supports.unclaimed` names each kind of base.
BASE_WORDS = {"static": "stationary", "sway": "swaying", "moving": "moving"}


def supports(method) -> Supports:
    """A method's claims (its ``supports`` attribute; the default :class:`Supports` when it has none)."""
    return getattr(method, "supports", None) or Supports()
