"""The .cgh viewer: GPU decode, GPU sort and Gaussian splatting with moderngl (window or headless).

Import :mod:`viewer.renderer` for the API; ``cgh view``, ``cgh render`` and ``cgh bench-viewer``
are the command-line entry points. Importing this package does not import moderngl.
"""
