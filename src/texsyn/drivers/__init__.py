"""Layer 4, synthesis drivers: each synthesis loop written once, the method's step passed in.

- :mod:`.alternating`: alternating projections (Heeger–Bergen, Portilla–Simoncelli, grouplets);
- :mod:`.raster`: raster-order patch loops (Efros–Leung, quilting, LG/CLG/RCLG);
- :mod:`.coarse_to_fine`: coarse-to-fine walks over a pyramid (cwt, Wei–Levoy, patch-valued
  wavelets, multiscale LG).

See ``docs/architecture.md``.
"""
