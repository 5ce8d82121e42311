"""The point methods by name, and the one dispatcher that runs any of them on a mesh.

A method is a :class:`PointMethod`: a function of one mesh's
:class:`MeshContext` (the mesh, its normals and mesh saliency, the rules,
its views' channels and combined maps when the method looks, the touch
model when it learns), and what it needs.  :func:`points_by_method` builds
the context once (one rendering, one set of channel maps per combination)
for any number of methods; :func:`interest_points` runs one.  Adding a
method is one ``POINT_METHODS.register`` call: the command line, the
experiment and the batch take it from the registry.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshsal.attention.rig import ViewChannels, attention_maps
from meshsal.mesh import Mesh
from meshsal.points import baselines
from meshsal.points.attend import attention_points
from meshsal.points.learned import candidate_pool, learned_points, point_features
from meshsal.points.record import InterestPoints
from meshsal.points.rules import PointOptions, Rules
from meshsal.points.select import TouchFilter, choose_without_views
from meshsal.points.workpiece import Workpiece
from meshsal.util.registry import Registry

__all__ = [
    "PointMethod",
    "MeshContext",
    "POINT_METHODS",
    "METHODS",
    "ATTENTION_METHODS",
    "MODEL_METHODS",
    "attention_combination",
    "points_by_method",
    "method_points",
    "interest_points",
]

#: The attention methods and the combination each uses (the deprecated ``PointOptions.combination`` still
#: changes "attention"'s, unless the method of that combination is asked for too).
ATTENTION_METHODS = {"attention": "equal", "attention_itti": "itti", "attention_learned": "learned"}


@dataclass(frozen=True, eq=False)
class MeshContext:
    """What a method may use on one mesh, computed once for every method of a call.

    ``piece`` holds the mesh and what is computed of it on first use (its
    scene, normals, mesh saliency, views); ``maps`` the combined saliency
    maps of each combination some method of the call asked for, keyed by
    :func:`_maps_key`; ``touch`` the touch check they share (None when the
    rules do not check touches).
    """

    piece: Workpiece
    rules: Rules
    options: PointOptions
    model: object = None
    maps: dict | None = None
    touch: TouchFilter | None = None

    @property
    def mesh(self) -> Mesh:
        return self.piece.mesh

    @property
    def vertex_normals(self) -> np.ndarray:
        return self.piece.vertex_normals

    @property
    def vertex_saliency(self) -> np.ndarray:
        return self.piece.vertex_saliency

    @property
    def seen(self) -> ViewChannels:
        return self.piece.seen

    def maps_of(self, combination: str, weights=None) -> np.ndarray:
        return self.maps[_maps_key(combination, weights)]


@dataclass(frozen=True)
class PointMethod:
    """One way to choose points.

    Attributes
    ----------
    choose : callable
        ``choose(name, context) -> InterestPoints``.
    combination : callable, optional
        ``combination(name, options, model) -> (combination, weights)``: the
        saliency maps the method reads (the views are rendered when set).
    needs_model : bool
        It reads a fitted ``meshsal.points.learned.TouchModel``.
    """

    choose: Callable
    combination: Callable | None = None
    needs_model: bool = False


def _maps_key(combination: str, weights) -> tuple:
    return combination, None if weights is None else tuple(sorted(weights.items()))


def attention_combination(method: str, combination: str = "equal") -> str:
    """The channel combination an attention method uses: its own, or ``combination`` for "attention" and others."""
    return ATTENTION_METHODS[method] if method in ATTENTION_METHODS and method != "attention" else combination


def _attention_maps_of(name, options, model):
    mode = attention_combination(name, options.combination)
    return mode, model.channel_weights if name == "attention_learned" else options.weights


def _attention(name, ctx: MeshContext) -> InterestPoints:
    mode, weights = _attention_maps_of(name, ctx.options, ctx.model)
    return attention_points(
        ctx.mesh,
        ctx.seen.views,
        ctx.maps_of(mode, weights),
        ctx.vertex_saliency,
        ctx.rules,
        combination=mode,
        method=name,
        touch=ctx.touch,
    )


def _learned(name, ctx: MeshContext) -> InterestPoints:
    pool = candidate_pool(ctx.mesh, ctx.rules.n)
    features = point_features(
        ctx.mesh,
        ctx.seen.views,
        ctx.seen.results,
        ctx.maps_of("equal"),
        ctx.vertex_saliency,
        pool,
        ctx.rules.min_spacing,
        ctx.rules.threshold,
    )
    return learned_points(ctx.mesh, pool, features, ctx.model, ctx.vertex_saliency, ctx.rules, touch=ctx.touch)


def _baseline(candidates):
    def choose(name, ctx: MeshContext) -> InterestPoints:
        first, field = candidates(
            ctx.mesh, ctx.vertex_normals, ctx.rules.n, np.random.default_rng(ctx.options.seed), ctx.vertex_saliency
        )
        return choose_without_views(
            ctx.mesh,
            ctx.vertex_normals,
            ctx.vertex_saliency,
            first,
            lambda i: field[i],
            ctx.rules,
            name,
            touch=ctx.touch,
        )

    return choose


#: The interest-point methods, each a :class:`PointMethod`.
POINT_METHODS = Registry("interest-point method")
POINT_METHODS.register(
    "attention", PointMethod(_attention, _attention_maps_of), "the paper's visual attention (equal channel weights)"
)
POINT_METHODS.register(
    "attention_itti",
    PointMethod(_attention, _attention_maps_of),
    "the paper's visual attention, each channel weighted by Itti's N(.)",
)
POINT_METHODS.register(
    "attention_learned",
    PointMethod(_attention, _attention_maps_of, needs_model=True),
    "the paper's visual attention, channel weights learned from touches",
)
POINT_METHODS.register(
    "learned",
    PointMethod(_learned, lambda name, options, model: ("equal", None), needs_model=True),
    "points by touch distinctiveness predicted from vision (meshsal.points.learned)",
)
POINT_METHODS.register(
    "random", PointMethod(_baseline(baselines.random_candidates)), "area-weighted random surface points"
)
POINT_METHODS.register("uniform", PointMethod(_baseline(baselines.uniform_candidates)), "farthest-point sampling")
POINT_METHODS.register(
    "mesh_saliency", PointMethod(_baseline(baselines.mesh_saliency_candidates)), "peaks of Lee et al.'s mesh saliency"
)
POINT_METHODS.register(
    "curvature", PointMethod(_baseline(baselines.curvature_candidates)), "peaks of absolute mean curvature"
)
METHODS = POINT_METHODS.names()
#: Methods that need a fitted ``meshsal.points.learned.TouchModel`` (``model=``).
MODEL_METHODS = tuple(e.name for e in POINT_METHODS if e.value.needs_model)


def points_by_method(
    mesh: Mesh | Workpiece,
    methods,
    options: PointOptions | None = None,
    *,
    model=None,
    vertex_saliency=None,
    seen: ViewChannels | None = None,
    scene=None,
    **changes,
) -> dict:
    """:func:`interest_points` of several methods on one mesh, rendering and computing channels once.

    Parameters
    ----------
    mesh : Mesh or Workpiece
        A :class:`~meshsal.points.workpiece.Workpiece` brings what is already
        computed of the mesh (its views at ``options.size``) and keeps what
        this call computes for the caller's next stages.
    methods : iterable of str, names in ``POINT_METHODS``
    options : PointOptions, optional
        Changed by any ``**changes`` (``n=``, ``seed=``, ``size=``... as its fields).
    model : meshsal.points.learned.TouchModel, optional
        Needed by "learned" and "attention_learned" (its channel weights).
    vertex_saliency : (n_vertices,) float64, optional
        Precomputed mesh saliency.
    seen : ViewChannels, optional
        The mesh's :func:`meshsal.attention.rig.view_channels` if already
        computed (else rendered here when a method looks).
    scene : optional
        The mesh's robust Embree scene (:func:`meshsal.mesh.embree.embree_scene`), which every
        method's touch check shares; built once here when omitted.

    Returns
    -------
    dict method -> InterestPoints, for each of ``methods`` (the same as one
    :func:`interest_points` call each)
    """
    options = (options or PointOptions()).replace(**changes)
    methods = list(dict.fromkeys(methods))
    if options.combination != "equal" and options.combination in ATTENTION_METHODS.values():
        own = next(m for m, c in ATTENTION_METHODS.items() if c == options.combination)
        warnings.warn(
            f"PointOptions.combination is deprecated and goes in 0.3: ask for the method {own!r} instead of "
            f"'attention' with combination {options.combination!r}. Until then it applies to 'attention' unless "
            f"{own!r} is asked for too (each method keeps its own combination)",
            FutureWarning,
            stacklevel=2,
        )
        if own in methods:
            options = options.replace(combination="equal")
    piece = _workpiece(mesh, options, scene, vertex_saliency, seen)
    chosen = {m: POINT_METHODS.get(m) for m in methods}
    rules = options.rules(piece.mesh)
    for m, method in chosen.items():
        if method.needs_model and model is None:
            raise ValueError(f"method {m!r} needs a fitted touch model (model=, a meshsal.points.learned.TouchModel)")
        if m == "attention" and options.combination == "learned" and options.weights is None:
            raise ValueError(
                "combination 'learned' needs channel weights (weights=, e.g. a TouchModel's channel_weights)"
            )
    size = getattr(model, "view_size", None)
    if size is not None and size != piece.view_size and any(method.needs_model for method in chosen.values()):
        warnings.warn(
            f"the touch model's features were measured on views of {size} pixels, these are {piece.view_size}: its "
            f"channel means differ with the size (render at its size: --view-size {size}, or size={size})",
            stacklevel=3,
        )
    wanted = {
        _maps_key(*method.combination(m, options, model)): method.combination(m, options, model)
        for m, method in chosen.items()
        if method.combination is not None
    }
    maps = {key: attention_maps(piece.seen, mode, weights) for key, (mode, weights) in wanted.items()}
    touch = TouchFilter(piece.mesh, rules, piece.scene) if rules.touch and chosen else None
    ctx = MeshContext(piece, rules, options, model, maps, touch)
    return {m: method.choose(m, ctx) for m, method in chosen.items()}


def _workpiece(mesh, options: PointOptions, scene, vertex_saliency, seen) -> Workpiece:
    """The caller's workpiece, or one of its mesh with what it gave; its views must be the options' size."""
    piece = Workpiece.of(
        mesh,
        scene=scene,
        vertex_saliency=vertex_saliency,
        seen=seen,
        view_size=options.size,
        threads=options.threads,
        quiet=options.quiet,
    )
    if piece.view_size != options.size:
        raise ValueError(
            f"the workpiece of {piece.mesh.name or 'the mesh'} renders {piece.view_size}-pixel views, but the "
            f"options ask for {options.size}: build it with view_size={options.size}"
        )
    return piece


def method_points(
    mesh: Mesh | Workpiece,
    methods,
    options: PointOptions,
    *,
    model=None,
    surveyed=None,
    vertex_saliency=None,
    seen=None,
    scene=None,
) -> dict:
    """:func:`points_by_method`, with "learned" chosen from a survey's pool when one is given (no rendering).

    The per-mesh stage that the experiment and the corpus batch share.

    Parameters
    ----------
    mesh : Mesh or Workpiece
        As in :func:`points_by_method`.
    methods : iterable of str, names in ``POINT_METHODS``
    options : PointOptions
    model : meshsal.points.learned.TouchModel, optional
    surveyed : optional
        Anything with ``pool`` ((k,) int vertex ids) and ``features`` ((k, len(FEATURES)) float), e.g. a
        ``classify.experiment.survey.Survey``: "learned" ranks that pool (:func:`learned_points`) instead
        of its own.
    vertex_saliency : (n_vertices,) float64, optional
        Precomputed mesh saliency.
    seen : ViewChannels, optional
        The mesh's channels if already computed.
    scene : optional
        The mesh's robust Embree scene, shared with the caller's imprints (built when omitted).

    Returns
    -------
    dict method -> InterestPoints, in the order of ``methods``

    Examples
    --------
    >>> import meshsal
    >>> cup = meshsal.objects.toys.make("cup")
    >>> picked = method_points(cup, ["uniform", "random"], PointOptions(n=5))
    >>> list(picked), len(picked["uniform"])
    (['uniform', 'random'], 5)
    """
    methods = list(methods)
    piece = _workpiece(mesh, options, scene, vertex_saliency, seen)
    by_survey = surveyed is not None and "learned" in methods
    picked = points_by_method(piece, [m for m in methods if not (by_survey and m == "learned")], options, model=model)
    if by_survey:
        picked["learned"] = learned_points(
            piece.mesh,
            surveyed.pool,
            surveyed.features,
            model,
            piece.vertex_saliency,
            n=options.n,
            pad_width=options.pad_width,
            scene=piece.scene,
        )
    return {m: picked[m] for m in methods}


def interest_points(
    mesh: Mesh,
    n: int | None = None,
    method: str = "attention",
    options: PointOptions | None = None,
    *,
    model=None,
    vertex_saliency=None,
    **changes,
) -> InterestPoints:
    """Choose ``n`` interest points on a mesh (:mod:`meshsal.points` for the pipeline).

    Parameters
    ----------
    mesh : Mesh
    n : int, optional
        How many points (default ``options.n``, 15); fewer only if the mesh cannot hold ``n`` at ``min_spacing``.
    method : str
        A name in ``POINT_METHODS``: "attention" (the paper's pipeline),
        "attention_itti" (the same with ``combination="itti"``),
        "attention_learned" (with a model's learned channel weights),
        "learned" (the candidates of :func:`meshsal.points.learned.candidate_pool`
        ranked by a model's predicted touch distinctiveness), or a baseline:
        "random", "uniform", "mesh_saliency", "curvature"
        (:mod:`meshsal.points.baselines`).  All keep the same rules.
    options : PointOptions, optional
        Everything else (spacing, pad, touch check, views, seed), changed by
        any ``**changes`` named as its fields (``size=64``, ``seed=3``...).
    model : meshsal.points.learned.TouchModel, optional
        Needed by "learned" and "attention_learned".
    vertex_saliency : (n_vertices,) float64, optional
        Precomputed mesh saliency.

    Returns
    -------
    InterestPoints

    Examples
    --------
    >>> import meshsal
    >>> pts = meshsal.interest_points(meshsal.objects.toys.make("cup"), n=15, size=64)
    >>> pts.positions.shape, pts.normals.shape, len(pts.views)
    ((15, 3), (15, 3), 15)
    """
    if n is not None:
        changes["n"] = n
    return points_by_method(mesh, [method], options, model=model, vertex_saliency=vertex_saliency, **changes)[method]
