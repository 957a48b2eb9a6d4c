import numpy as np, sys
sys.path.insert(0,"scratch")
from phonestereo.features.subpixel import refine_lk, bspline_coefficients
rng=np.random.default_rng(1)
f=np.fft.fft2(rng.standard_normal((120,160))); fy,fx=np.fft.fftfreq(120)[:,None],np.fft.fftfreq(160)[None,:]
lp=np.exp(-2*np.pi**2*1.5**2*(fx**2+fy**2))
L=(128+600*np.real(np.fft.ifft2(f*lp))).astype(np.float32); R=(128+600*np.real(np.fft.ifft2(f*lp*np.exp(2j*np.pi*fx*5.3)))).astype(np.float32)
xy=np.stack(np.meshgrid(np.arange(30,130,10),np.arange(30,90,10)),-1).reshape(-1,2)
for slant in (True, False):
    ref=refine_lk(L,None,bspline_coefficients(R),xy,np.full(len(xy),5.0),np.zeros(len(xy)),slant=slant)
    print(slant, ref.converged.mean(), np.nanmax(np.abs((ref.influence[:,0]**2).sum(1)/ref.cov_unit[:,0,0]-1)), np.nanmax(np.abs((ref.influence[:,1]**2).sum(1)/ref.cov_unit[:,1,1]-1)))
    # perturbation check
    n = rng.standard_normal(L.shape).astype(np.float32)*0.5
    ref2=refine_lk(L+n,None,bspline_coefficients(R),xy,np.full(len(xy),5.0),np.zeros(len(xy)),slant=slant)
    r=7; pred=np.array([ (ref.influence[k,0]*n[y-r:y+r+1,x-r:x+r+1].ravel()).sum() for k,(x,y) in enumerate(xy)])
    print(np.corrcoef(pred, ref2.d-ref.d)[0,1], np.std(pred), np.std(ref2.d-ref.d))
