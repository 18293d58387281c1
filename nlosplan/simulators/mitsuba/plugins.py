"""Mitsuba plugins of the twin: a relay-wall meter with given points, a retroreflective BSDF.

Registered by :func:`register` once a variant is set (never at import).

``nlosplan_point_meter``
    An ``nlos_capture_meter`` whose film pixels are arbitrary points of the
    relay wall (the wall hits of the LiDAR's zone sub-pixel rays), instead of
    a uniform UV grid of the whole wall: the twin spends its samples on wall
    the zones see. Points are handed over by key through :data:`POINT_SETS`.

``nlosplan_nlos_path``
    mitransient's ``transient_nlos_path`` with one fix: with
    ``account_first_and_last_bounces`` its next-event estimation adds the
    last leg to the caller's path length *in place* (``distance += ...`` on
    the loop variable), so every later vertex of the path is too late by the
    previous vertices' light-to-LiDAR distances (mitransient 1.3.1: three-
    bounce returns land ~0.5-0.9 m of optical path late). The subclass hands
    next-event estimation a copy.

``nlosplan_retro``
    A retroreflector on a Lambertian base: of the irradiance ``E`` arriving
    from ``w_l`` a fraction ``albedo`` is sent back in a von Mises-Fisher
    lobe ``p(w)`` around ``w_l`` (``kappa = 1 / sigma^2``, ``sigma = FWHM /
    2.3548`` in radians) and a fraction ``diffuse`` is scattered diffusely,
    the model of the fast backend. Outgoing radiance ``L(w_c) = albedo
    p(w_c) E / cos(w_c) + diffuse E / pi``, so Mitsuba's ``eval`` (``f cos``
    of the light-side direction) is ``albedo p cos(w_l) / cos(w_c) + diffuse
    cos(w_l) / pi``; ``sample`` picks the lobe or the cosine hemisphere in
    proportion to the two albedos and weights by the mixture's pdf.
"""

from __future__ import annotations

import math

import numpy as np

#: Wall points per meter, by key: ``(N, 3)`` float arrays (world, metres), pixel ``k`` = film index ``k``.
POINT_SETS: dict[str, np.ndarray] = {}

_REGISTERED: set[str] = set()


def vmf_kappa(lobe_fwhm_deg: float) -> float:
    """Concentration of the von Mises-Fisher lobe with the given angular FWHM (degrees)."""
    sigma = math.radians(lobe_fwhm_deg) / 2.3548200450309493
    return 1.0 / (sigma * sigma)


def register(mi) -> None:
    """Register the plugins with the current variant of ``mi`` (idempotent)."""
    if mi.variant() in _REGISTERED:
        return
    import drjit as dr
    from mitransient.integrators.transientnlospath import TransientNLOSPath
    from mitransient.sensors.nloscapturemeter import NLOSCaptureMeter

    class NlosPath(TransientNLOSPath):
        def emitter_nee_sample(self, *args, **kwargs):
            # the path length is the 8th positional parameter ('distance') of the parent's method
            if "distance" in kwargs:
                kwargs["distance"] = kwargs["distance"] + 0.0
            else:
                args = args[:7] + (args[7] + 0.0,) + args[8:]
            return super().emitter_nee_sample(*args, **kwargs)

    class PointMeter(NLOSCaptureMeter):
        def __init__(self, props):
            super().__init__(props)
            pts = np.asarray(POINT_SETS[props.get("points_key")], dtype=np.float32)
            self._points = mi.Point3f(pts[:, 0], pts[:, 1], pts[:, 2])
            self._w, self._h = int(self.film_size[0]), int(self.film_size[1])
            if pts.shape[0] != self._w * self._h:
                raise ValueError(f"point meter: {pts.shape[0]} points for a {self._w}x{self._h} film")

        def _sample_direction(self, time, sample, active):
            origin = self._sensor_origin()
            ix = mi.UInt32(dr.clip(dr.floor(sample.x * self._w), 0, self._w - 1))
            iy = mi.UInt32(dr.clip(dr.floor(sample.y * self._h), 0, self._h - 1))
            target = dr.gather(mi.Point3f, self._points, iy * self._w + ix, active)
            direction = target - origin
            distance = dr.norm(direction)
            return distance, direction / distance

    class Retro(mi.BSDF):
        def __init__(self, props):
            super().__init__(props)
            self.albedo = float(props.get("albedo", 0.5))
            self.diffuse = float(props.get("diffuse", 0.0))
            self.kappa = float(props.get("kappa", 1000.0))
            total = self.albedo + self.diffuse
            self.p_lobe = self.albedo / total if total > 0 else 1.0  # probability of sampling the lobe
            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [glossy, diffuse] if self.diffuse > 0 else [glossy]
            self.m_flags = (glossy | diffuse) if self.diffuse > 0 else glossy

        def _lobe(self, wi, wo):
            k = self.kappa
            one_minus_cos = 0.5 * dr.squared_norm(wo - wi)  # accurate near the peak
            norm = k / (2.0 * math.pi * (1.0 - math.exp(-2.0 * k)))
            return norm * dr.exp(-k * one_minus_cos)

        def sample(self, ctx, si, sample1, sample2, active=True):
            k = self.kappa
            cos_i = mi.Frame3f.cos_theta(si.wi)
            w = 1.0 + dr.log(dr.maximum(sample2.x + (1.0 - sample2.x) * math.exp(-2.0 * k), 1e-30)) / k
            w = dr.clip(w, -1.0, 1.0)
            s = dr.sqrt(dr.maximum(1.0 - w * w, 0.0))
            phi = 2.0 * math.pi * sample2.y
            lobe_wo = mi.Frame3f(si.wi).to_world(mi.Vector3f(s * dr.cos(phi), s * dr.sin(phi), w))
            if self.diffuse > 0:  # the component is chosen with sample1, as Mitsuba's own mixtures do
                pick_lobe = sample1 < self.p_lobe
                wo = dr.select(pick_lobe, lobe_wo, mi.warp.square_to_cosine_hemisphere(sample2))
            else:
                pick_lobe = mi.Bool(True)
                wo = lobe_wo
            cos_o = mi.Frame3f.cos_theta(wo)
            ok = active & (cos_i > 0) & (cos_o > 0)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            bs.pdf = dr.select(ok, self._pdf(si.wi, wo, cos_o), 0.0)
            bs.eta = 1.0
            bs.sampled_type = dr.select(pick_lobe, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                        mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
            bs.sampled_component = dr.select(pick_lobe, mi.UInt32(0), mi.UInt32(1))
            value = self._value(si.wi, wo, cos_i, cos_o)
            weight = dr.select(ok, value / dr.maximum(bs.pdf, 1e-30), 0.0)
            return bs, mi.Spectrum(weight)

        def _value(self, wi, wo, cos_i, cos_o):
            """``f cos(wo)``: the lobe's ``albedo p cos_o / cos_i`` plus the base's ``diffuse cos_o / pi``."""
            val = self.albedo * self._lobe(wi, wo) * cos_o / dr.maximum(cos_i, 1e-12)
            return val + self.diffuse * cos_o / math.pi if self.diffuse > 0 else val

        def _pdf(self, wi, wo, cos_o):
            lobe = self._lobe(wi, wo)
            return self.p_lobe * lobe + (1.0 - self.p_lobe) * cos_o / math.pi if self.diffuse > 0 else lobe

        def eval(self, ctx, si, wo, active=True):
            cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            ok = active & (cos_i > 0) & (cos_o > 0)
            return mi.Spectrum(dr.select(ok, self._value(si.wi, wo, cos_i, cos_o), 0.0))

        def pdf(self, ctx, si, wo, active=True):
            cos_o = mi.Frame3f.cos_theta(wo)
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (cos_o > 0)
            return dr.select(ok, self._pdf(si.wi, wo, cos_o), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            """No differentiable parameters are exposed (the lobe is fixed per scene)."""

        def parameters_changed(self, keys):
            """Nothing is cached from parameters, so nothing to update."""

        def to_string(self):
            return f"NlosplanRetro[albedo={self.albedo}, diffuse={self.diffuse}, kappa={self.kappa}]"

    mi.register_integrator("nlosplan_nlos_path", lambda props: NlosPath(props))
    mi.register_sensor("nlosplan_point_meter", lambda props: PointMeter(props))
    mi.register_bsdf("nlosplan_retro", lambda props: Retro(props))
    _REGISTERED.add(mi.variant())
