import numpy as np, healpy as hp, ducc0
L = 256; nth = 2 * L + 2; nph = 16
fw = np.radians(1.0)
bl = hp.gauss_beam(fw, lmax=L)
l = np.arange(L + 1)
t = np.zeros((1, hp.Alm.getsize(L, 4)), complex); t[0, :L + 1] = np.sqrt((2 * l + 1) / (4 * np.pi)) * bl
T = ducc0.sht.synthesis_2d(alm=t, spin=0, lmax=L, mmax=4, geometry="GL", ntheta=nth, nphi=nph)[0]
phi = 2 * np.pi * np.arange(nph) / nph
P = T * np.exp(-2j * phi)[None]  # spin +2 field Q+iU = f e^{-2i phi}
eb = ducc0.sht.analysis_2d(map=np.stack([P.real, P.imag]), spin=2, lmax=L, mmax=4, geometry="GL")
i2 = hp.Alm.getidx(L, l[2:], 2)
pminus2 = -(eb[0, i2] - 1j * eb[1, i2])  # P-[l, 2]
pplus_m2 = np.conj(pminus2)             # P+[l, -2] = (-1)^2 conj(P-[l, 2])
ratio = pplus_m2 / t[0, l[2:]]
print("P+[l,-2] / T[l,0] at l = 2, 10, 50, 100, 200:", np.round(ratio[[0, 8, 48, 98, 198]], 6))
sig = fw / np.sqrt(8 * np.log(2))
print("polarized/T window exp(2 sigma^2)-ish:", np.exp(2 * sig ** 2), " healpy ratio at l=100:", hp.gauss_beam(fw, 256, pol=True)[100, 1] / bl[100])
