"""The reference EMVA 1288 analysis of a data set, run by ``tests/camera_models/test_emva.py``
in its own interpreter (the ``emva1288`` package needs numpy < 2).

Usage: ``python emva_reference.py DESCRIPTOR PIXEL_AREA_UM2``; prints the measured QE (0-1),
K (DN/e⁻), dark noise (e⁻) and saturation (e⁻) as JSON.
"""

import json
import logging
import sys

from emva1288.process import Data1288, LoadImageData, ParseEmvaDescriptorFile, Results1288

parsed = ParseEmvaDescriptorFile(sys.argv[1], loglevel=logging.ERROR)
data = Data1288(LoadImageData(parsed.images, loglevel=logging.ERROR).data, loglevel=logging.ERROR)
results = Results1288(data.data, pixel_area=float(sys.argv[2]), loglevel=logging.ERROR)
print(json.dumps({"qe": results.QE / 100.0, "K_DN_per_e": results.K, "dark_noise_e": results.sigma_d,
                  "saturation_e": results.u_e_sat}))  # fmt: skip
