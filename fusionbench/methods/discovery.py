"""Method discovery: the registered methods (entry points), ``module:Class`` paths, their constructor options and
named variants. What a method *is* (the protocols, :class:`fusionbench.methods.aligner.AlignmentResult`) and building
one (:func:`fusionbench.methods.aligner.load_method`) are in :mod:`fusionbench.methods.aligner`, which re-exports
these."""

from __future__ import annotations

import importlib
import inspect
from importlib.metadata import entry_points

#: The entry-point group of alignment methods (and navigators).
METHODS_GROUP = "fusionbench.methods"


def available_methods():
    """Registered methods: ``{name: entry point}`` from the ``fusionbench.methods`` group."""
    return {ep.name: ep for ep in entry_points(group=METHODS_GROUP)}


def entry_class(group: str, spec: str, what: str = "method"):
    """The class registered by name in the entry-point ``group``, or given as ``module:Class``.

    Raises
    ------
    ValueError
        One line naming ``what`` and the spec, and what is available.
    """
    found = {ep.name: ep for ep in entry_points(group=group)}
    if spec in found:
        return found[spec].load()
    if ":" in spec:
        mod, _, attr = spec.partition(":")
        try:
            return getattr(importlib.import_module(mod), attr)
        except (ImportError, AttributeError, ValueError, SyntaxError) as exc:
            raise ValueError(f"{what} {spec!r}: cannot import ({type(exc).__name__}: "
                             f"{' '.join(str(exc).split())})") from None
    raise ValueError(f"{what} {spec!r}: expected one of {sorted(found)} or a module:Class path")


def load_entry(group: str, spec: str, what: str = "method", **options):
    """Instantiate :func:`entry_class` with ``options``."""
    return entry_class(group, spec, what)(**options)


def takes_option(cls, option: str) -> bool:
    """Whether a method class's constructor has the option ``option``."""
    try:
        return option in inspect.signature(cls).parameters
    except (TypeError, ValueError):
        return False


def unknown_option(cls, options):
    """The first of ``options`` (names) that the constructor of ``cls`` does not take, and the names it takes
    (sorted): ``(None, names)`` when it takes them all, or any keyword (``**kwargs``)."""
    try:
        params = inspect.signature(cls).parameters
    except (TypeError, ValueError):
        return None, []
    kinds = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    names = sorted(k for k, p in params.items() if p.kind not in kinds)
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return None, names
    return next((key for key in options if key not in params), None), names


def uses_noise_model(cls) -> bool:
    """Whether a method class takes an IMU model (its constructor has an ``imu`` option)."""
    return takes_option(cls, "imu")


def variant(base, class_name: str, name: str, description: str, **options):
    """A named variant of the method class ``base``: the same method with other default options.

    The variant is a subclass whose constructor defaults are ``options`` (any of them can still be
    overridden); ``variant_of`` and ``variant_options`` say what it is, so ``fusionbench list`` can show
    it. Assign it to the module attribute ``class_name`` of ``base``'s module (so it pickles to workers)
    and register it in the ``fusionbench.methods`` entry-point group under ``name``.
    """
    defaults = dict(options)

    def __init__(self, **kw):
        base.__init__(self, **{**defaults, **kw})

    sig = inspect.signature(base.__init__)  # the base's options, with the variant's defaults
    __init__.__signature__ = sig.replace(parameters=[
        p.replace(default=defaults[p.name]) if p.name in defaults else p for p in sig.parameters.values()])

    doc = (f"{description}\n\nNamed variant ``{name}`` of :class:`{base.__name__}` (``{base.name}``) with "
           + ", ".join(f"``{k}={v!r}``" for k, v in defaults.items()) + "; any option can still be given.")
    return type(class_name, (base,), {"name": name, "description": description, "variant_of": base.name,
                                      "variant_options": defaults, "__init__": __init__, "__doc__": doc,
                                      "__module__": base.__module__, "__qualname__": class_name})
