"""Bag of SuperPoints: incremental vocabulary, DP word tree, hierarchical k-means baseline, tf-idf database.
May import: numpy, scikit-learn, faiss and the base modules (types, errors, atomic); never io or another stage.

Public API (docs/CONTRACTS.md): :func:`train_vocabulary`, :func:`train_hkmeans`,
:class:`Vocabulary` (``quantize``, ``save``, ``load``, ``len``), :class:`BowDatabase`
(``add``, ``query``) and :class:`BowVector`.
"""
from .bow import BowVector, bow_similarity
from .config import VocabConfig
from .database import BowDatabase
from .descriptors import as_unit_vectors
from .vocabulary import Vocabulary, train_hkmeans, train_vocabulary
from .words import IncrementalWords

__all__ = [
    "VocabConfig", "BowDatabase", "BowVector", "bow_similarity", "as_unit_vectors",
    "Vocabulary", "train_hkmeans", "train_vocabulary", "IncrementalWords",
]
