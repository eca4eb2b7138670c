"""slam-lcd: Bag of SuperPoints loop-closure detection with graph verification, as a GTSAM back end."""
__version__ = "0.1.0"
