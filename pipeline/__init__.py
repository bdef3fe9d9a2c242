"""guide: learned autonomous exploration with global graph inference (GUIDE, Che et al.)."""

__version__ = "0.1.0"
