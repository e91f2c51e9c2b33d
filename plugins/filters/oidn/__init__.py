"""``oidn``: Intel Open Image Denoise through ``pyoidn`` (the learned-denoiser baseline and peer).

The RT filter with albedo and normal auxiliary images, HDR mode, quality ``fast`` by default
(``high`` available). Needs the ``peers`` extra; listed as broken where pyoidn is missing.
"""

import importlib.util

import numpy as np

from harness import FilterSpec, Param, hookimpl

# pyoidn imports torch (seconds): look it up now, so a missing install marks this plugin broken,
# and import it when a filter is built.
if importlib.util.find_spec("pyoidn") is None:
    raise ImportError("the oidn filter needs pyoidn (pip install 'denoise-harness[peers]')")

_QUALITY = ("fast", "balanced", "high")
PARAMS = {"quality": Param("fast", choices=_QUALITY)}


class OIDN:
    """Denoise ``color`` with OIDN's RT filter, guided by ``albedo`` and ``normal``.

    Parameters
    ----------
    backend : {"cpu"}
    quality : {"fast", "balanced", "high"}
    """

    def __init__(self, backend="cpu", quality="fast"):
        if backend != "cpu":
            raise ValueError(f"oidn: unsupported backend {backend!r}")
        if quality not in _QUALITY:
            raise ValueError(f"oidn: quality must be one of {list(_QUALITY)}, got {quality!r}")
        import pyoidn

        self._oidn = pyoidn
        self.quality = quality
        self._device = pyoidn.Device()
        self._device.commit()

    def reset(self):
        """Stateless."""

    def __deepcopy__(self, memo):
        return OIDN(quality=self.quality)

    def __call__(self, frame, sampler=None):
        color = np.ascontiguousarray(np.clip(frame["color"], 0.0, 6.0e4), np.float32)
        albedo = np.ascontiguousarray(np.clip(frame["albedo"], 0.0, 1.0), np.float32)
        normal = np.ascontiguousarray(frame["normal"], np.float32)
        pyoidn = self._oidn
        out = np.zeros_like(color)
        filt = pyoidn.Filter(self._device, "RT")
        filt.set_image(pyoidn.OIDN_IMAGE_COLOR, color, pyoidn.OIDN_FORMAT_FLOAT3)
        filt.set_image(pyoidn.OIDN_IMAGE_ALBEDO, albedo, pyoidn.OIDN_FORMAT_FLOAT3)
        filt.set_image(pyoidn.OIDN_IMAGE_NORMAL, normal, pyoidn.OIDN_FORMAT_FLOAT3)
        filt.set_image(pyoidn.OIDN_IMAGE_OUTPUT, out, pyoidn.OIDN_FORMAT_FLOAT3)
        filt.set_bool("hdr", True)
        filt.set_quality(getattr(pyoidn, f"OIDN_QUALITY_{self.quality.upper()}"))
        filt.commit()
        filt.execute()
        filt.release()
        return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="oidn",
            version="1.0+pyoidn",
            factory=OIDN,
            requires={"color", "albedo", "normal"},
            params=PARAMS,
            presets={"high": {"quality": "high"}},
            xfail_checks={
                "check_constant_image": "a learned denoiser does not reproduce a constant "
                "image exactly (measured error 0.36 on a 0.75 constant)",
                "check_zero_image": "the network adds a bias of about 1e-3 to an all-zero image",
            },
            description="Intel Open Image Denoise RT filter, albedo+normal (peer)",
        )
    ]
