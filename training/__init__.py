"""Training of the compact appearance model: reference splatter, datasets, model, evaluation.

Needs the ``training`` extra (torch). ``import training`` itself imports nothing heavy.
"""
