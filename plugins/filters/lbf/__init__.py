"""The ``lbf`` filter plugin: a learned per-pixel cross-bilateral filter (Kalantari et al. 2015)."""

from harness import FilterSpec, Param, hookimpl

from .denoiser import LBFFilter

VERSION = "2.0"
PARAMS = {
    "radius": Param(5, min=0, max=64, doc="filter window radius in pixels (weights trained with 5)"),
    "weights": Param(None, type="str", doc="weights file; null for the shipped weights"),
    "visibility": Param("auto", choices=("auto", "standin")),
}


#: options of ``denoise-bench train lbf -o KEY=VALUE``
TRAIN_OPTIONS = ("real",)


def train_lbf(seed: int = 0, output=None, quick: bool = False, **options):
    """Train LBF and write a weights file (``denoise-bench train lbf [-o real=false]``).

    ``real`` (default true): include the real scenes of the shipped recipe; false trains on
    procedural data alone. See :func:`plugins.filters.lbf.train.train`.
    """
    unknown = sorted(set(options) - set(TRAIN_OPTIONS))
    if unknown:
        raise ValueError(f"lbf trainer: unknown option(s) {unknown}; it takes {list(TRAIN_OPTIONS)}")
    from .train import train as _train

    return _train(seed=seed, output=output, quick=quick, **options)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="lbf",
            version=VERSION,
            factory=LBFFilter,
            requires={"color", "normal", "albedo"},
            optional={"position", "variance", "depth", "visibility", "spp"},
            full_guides={"normal", "albedo", "position", "variance"},
            temporal=False,
            backends=("cpu", "cuda"),
            params=PARAMS,
            stage_timing=True,
            presets={"paper-window": {"radius": 27}, "small": {"radius": 3}},
            description="learned filter parameters: an MLP predicts per-pixel bilateral bandwidths",
            trainer=train_lbf,
        )
    ]
