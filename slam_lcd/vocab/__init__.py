"""Bag of SuperPoints: incremental vocabulary, DP word tree, hierarchical k-means baseline, tf-idf database.
May import: numpy, scikit-learn, faiss and the base modules (types, errors, atomic); never io or another stage.

Public API (docs/CONTRACTS.md): :func:`train_vocabulary`, :func:`train_hkmeans`,
:class:`Vocabulary` (``quantize``, ``save``, ``load``, ``len``), :class:`BowDatabase`
(``add``, ``query``) and :class:`BowVector`.

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import VocabConfig

_LAZY = {
    "BowVector": ".bow",
    "bow_similarity": ".bow",
    "BowDatabase": ".database",
    "as_unit_vectors": ".descriptors",
    "Vocabulary": ".vocabulary",
    "train_hkmeans": ".vocabulary",
    "train_vocabulary": ".vocabulary",
    "IncrementalWords": ".words",
}

__all__ = ["VocabConfig", *_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
