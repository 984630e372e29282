"""Automatic aerotriangulation (PHODIS AT): block projects, pyramids, interior
orientation, tie points by interest operator, feature-based and least-squares
matching, and synthetic blocks with truth.

Conventions (every module of this package follows them):

Pixel coordinates
    ``(col, row)`` of a raster: ``col`` to the right, ``row`` down, the centre
    of the top-left pixel at ``(0, 0)`` (pixel centres at integers). Level ``k``
    of an image pyramid has pixel ``(c_k, r_k)`` with
    ``c_0 = 2**k * c_k + (2**k - 1) / 2`` (the centres of averaged blocks).
Photo coordinates
    ``(x, y)`` in millimetres in the image plane, ``x`` right and ``y`` up when
    the photo is viewed as a positive, origin at the centre of the fiducial
    marks (film) or of the sensor (digital); the principal point ``(x0, y0)``
    is given in this system. These are the photo coordinates of
    :mod:`apygis.orient.rotation` and :mod:`apygis.orient.collinearity`.
Pixel -> photo
    an affine (or projective) transform per image (:class:`PixelTransform`),
    found by interior orientation for film, and fixed by the pixel pitch for a
    digital camera: ``x = (col - (W - 1) / 2) * p``, ``y = ((H - 1) / 2 - row) * p``.
"""
