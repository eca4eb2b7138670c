"""The Kinect v1 depth-error model the TUM layout's depth images are written with.

Why: TUM RGB-D was recorded with a Kinect v1 (structured light), whose depth is far from
exact; rendered depth with only millimetre rounding makes the RGB-D VO unrealistically
good. The model is the published one, not fitted to this project:

- axial noise ``sigma_z(z) = 0.0012 + 0.0019 (z - 0.4)^2`` m, Gaussian, independent per
  pixel (Nguyen, Izadi, Lovell, "Modeling Kinect Sensor Noise for Improved 3D
  Reconstruction and Tracking", 3DIMPVT 2012, eq. for a surface facing the camera);
- disparity quantisation: the sensor measures disparity in 1/8-pixel steps, a depth
  resolution of ``2.85e-3 z^2`` m (Khoshelham & Elberink, "Accuracy and Resolution of
  Kinect Depth Data for Indoor Mapping Applications", Sensors 2012); depth is written on
  that grid, i.e. inverse depth rounded to steps of ``2.85e-3`` 1/m;
- no reading (0) outside the working range ``0.5-4.5`` m.

Not modelled: the lateral (edge) noise, the noise's growth with the surface's incidence
angle and its spatial correlation (neighbouring pixels share the speckle window), missing
returns on dark or shiny surfaces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class KinectDepthModel:
    """Axial noise, disparity steps and working range of a Kinect v1 (defaults: the published values)."""

    sigma_const_m: float = 0.0012  # Nguyen et al. 2012: sigma_z = a + b (z - z0)^2
    sigma_quad_per_m: float = 0.0019
    sigma_z0_m: float = 0.4
    inverse_depth_step_per_m: float = 2.85e-3  # Khoshelham & Elberink 2012: resolution 2.85e-3 z^2 (1/8 px disparity)
    min_range_m: float = 0.5
    max_range_m: float = 4.5

    def describe(self) -> str:
        return (f"Kinect v1 model: sigma_z = {self.sigma_const_m:g} + {self.sigma_quad_per_m:g} (z - "
                f"{self.sigma_z0_m:g})^2 m, inverse-depth steps {self.inverse_depth_step_per_m:g} 1/m, "
                f"0 outside {self.min_range_m:g}-{self.max_range_m:g} m")

    def sigma_z(self, z: np.ndarray) -> np.ndarray:
        """Axial noise (m) at depth ``z`` (m)."""
        return self.sigma_const_m + self.sigma_quad_per_m * (np.asarray(z, np.float64) - self.sigma_z0_m) ** 2

    def measure(self, z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """What the sensor reports for true depth ``z`` (float metres; NaN/inf = nothing): metres, 0 = no reading."""
        z = np.nan_to_num(np.asarray(z, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        noisy = z + rng.standard_normal(z.shape) * self.sigma_z(z)
        q = self.inverse_depth_step_per_m
        with np.errstate(divide="ignore", invalid="ignore"):
            steps = np.round(1.0 / (noisy * q))  # the disparity the sensor measured, on its grid
            out = 1.0 / (steps * q)
        valid = (z > 0) & np.isfinite(out) & (out >= self.min_range_m) & (out <= self.max_range_m)
        return np.where(valid, out, 0.0)


KINECT_V1 = KinectDepthModel()


def depth_mm(z: np.ndarray) -> np.ndarray:
    """Metres (NaN/inf/0 = nothing) as a 16UC1 millimetre image (0 = no reading)."""
    return np.clip(np.round(np.nan_to_num(z, nan=0.0, posinf=0.0, neginf=0.0) * 1000.0), 0, 65535).astype(np.uint16)
