"""Still stretches and gravity consistency together (docs/experiments/learning.md, "Each recording's own
bias"): the still estimate first, then gravity consistency on what it leaves with its prior narrowed to
the still estimate's trust (0.001 or 0.003 rad/s); recordings without a still stretch get gravity
consistency alone. Prints the mean bias error [mrad/s] per device and split, segments >= 30 s.

    IMU_LEARN_DATA=<root> python experiments/bias_combined.py
"""
import os
from dataclasses import replace

import numpy as np

from imu_learn.core.bias_gravity import GravitySettings, gravity_bias
from imu_learn.core.still import BIAS_SETTINGS, still_bias
from imu_learn.train.bias_data import load_device, training_mean

for sp in ["train","test"]:
  for d in ["euroc","fetch","tumvi","broad"]:
    recs=load_device(d,os.environ.get("IMU_LEARN_DATA", "data")); m=training_mean(recs["train"])
    res={k:[] for k in ["mean","still","gravity","combo1","combo3"]}
    for r in recs[sp]:
        s=r.seg
        if s.duration_s<30: continue
        g0=s.gyro-m
        st=still_bias(s.t_ns,g0,s.acc,replace(BIAS_SETTINGS,gravity=r.gravity)).gyro_bias
        gr=gravity_bias(s.t_ns,g0,s.acc).gyro_bias
        st0=np.zeros(3) if st is None else st
        res["mean"].append(np.zeros(3)); res["still"].append(st0); res["gravity"].append(gr)
        for k,ps in (("combo1",0.001),("combo3",0.003)):
            if st is None: res[k].append(gr)
            else: res[k].append(st+gravity_bias(s.t_ns,g0-st,s.acc,GravitySettings(prior_sigma=ps)).gyro_bias)
        for k in res: res[k][-1]=np.linalg.norm(m+res[k][-1]-r.gyro_bias)
    print(sp,d," ".join(f"{k} {np.mean(v)*1e3:.2f}" for k,v in res.items()),flush=True)
