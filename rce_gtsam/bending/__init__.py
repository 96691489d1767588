"""Stage 3, bending: smoothed positions -> signed turning angle at every joint (deg), its deviation from rest,
outlier mask and propagated variance (:mod:`.angles`), on the branch's rest geometry (:mod:`.geometry`).
"""
