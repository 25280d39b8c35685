#!/usr/bin/env python3
"""Prints common/data/conductors.csv rows: the RGB eta and k that Mitsuba 3 (scalar_rgb) gives each named conductor."""
import mitsuba as mi
mi.set_variant("scalar_rgb")
names = "a-C Ag Al AlAs AlAs_palik AlSb AlSb_palik Au Be Cr CsI Cu Cu_palik Cu2O CuO d-C Hg HgTe Ir K Li MgO Mo Na_palik Nb Ni_palik Rh Se SiC SnTe Ta Te ThF4 TiC TiN TiO2 VC V VN W".split()
for n in names:
    try:
        p = mi.traverse(mi.load_dict({"type": "conductor", "material": n}))
        e, k = p["eta.value"], p["k.value"]
        print(",".join([n] + ["%.6g" % float(x) for x in list(e) + list(k)]))
    except Exception as ex:
        pass
