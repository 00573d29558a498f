#!/usr/bin/env python3
# The TUM fr3 cabinet floor residual taken apart: the pattern fixed in the
# image (16-px cells over the frames) and the relief fixed on the floor
# (10-cm squares, motion-capture poses), with split-half correlations and
# the autocorrelation left after each. Needs numpy and Pillow. Figures quoted
# in tests/real_noise.rs and docs/method.md come from this script.
import numpy as np
from PIL import Image

import os
D=os.path.realpath(os.path.join(os.path.dirname(__file__), '../../shared/data/real/tum-fr3-cabinet'))+'/'
fx,fy,cx,cy=535.4,539.2,320.1,247.6
RAW=0.00307
poses=[list(map(float,l.split())) for l in open(D+'truth_cam_poses.txt') if l.strip()]
def R(q):
    x,y,z,w=q
    return np.array([[1-2*(y*y+z*z),2*(x*y-z*w),2*(x*z+y*w)],[2*(x*y+z*w),1-2*(x*x+z*z),2*(y*z-x*w)],[2*(x*z-y*w),2*(y*z+x*w),1-2*(x*x+y*y)]])
H,W=480,640
vv,uu=np.mgrid[0:H,0:W]
rx=(uu-cx)/fx; ry=(vv-cy)/fy
frames=[]
for i,p in enumerate(poses):
    z=np.array(Image.open(D+'depth_imgs/%04d_depth_raw.png'%i)).astype(float)/5000
    Rw=R(p[4:8]); t=np.array(p[1:4])
    P=np.stack([rx*z,ry*z,z],-1)
    Pw=P@Rw.T+t
    valid=z>0
    # floor candidates: world z within 8 cm of the floor height (mode)
    zs=Pw[...,2][valid]
    hist,edges=np.histogram(zs,bins=np.arange(-0.5,0.5,0.01))
    fz=edges[np.argmax(hist)]+0.005
    m=valid&(np.abs(Pw[...,2]-fz)<0.08)
    w=np.where(valid,1/np.maximum(z,1e-9),0)
    A=np.stack([uu[m],vv[m],np.ones(m.sum())],1)
    for it in range(4):
        c,*_=np.linalg.lstsq(A,w[m],rcond=None)
        pl=c[0]*uu+c[1]*vv+c[2]
        res=(w-pl)/RAW
        m=m&(np.abs(res)<3) if it==0 else valid&(np.abs(res)<3)&(np.abs(Pw[...,2]-fz)<0.08)
        A=np.stack([uu[m],vv[m],np.ones(m.sum())],1)
    frames.append(dict(res=np.where(m,res,np.nan),Pw=Pw,m=m))
print('frames',len(frames), 'mean floor px', np.mean([f['m'].sum() for f in frames]))
np.save('/tmp/floor-relief-res.npy',np.stack([f['res'] for f in frames]))
np.save('/tmp/floor-relief-xy.npy',np.stack([f['Pw'][...,:2] for f in frames]).astype(np.float32))

# metric vertical residual: displacement of the point along its ray, vertical part
hres=[]
for i,(p,f) in enumerate(zip(poses,frames)):
    Rw=R(p[4:8])
    z=np.array(Image.open(D+'depth_imgs/%04d_depth_raw.png'%i)).astype(float)/5000
    up=(Rw[2,0]*rx+Rw[2,1]*ry+Rw[2,2])
    hres.append(-f['res']*RAW*z*z*up*1000)  # mm
hres=np.stack(hres)
res=np.stack([f['res'] for f in frames])
xy=np.stack([f['Pw'][...,:2] for f in frames])
N=len(frames)
def cellmap(r,c=16):
    a=r.reshape(N,H//c,c,W//c,c)
    return np.nanmean(a,axis=(2,4))
def autocorr(r,lags=(1,2,4,8,16,32)):
    out=[]
    for L in lags:
        a=r[:,:,:-L];b=r[:,:,L:]
        ok=~np.isnan(a)&~np.isnan(b)
        # per-frame mean removed
        out.append(np.sum((a*b)[ok])/np.sqrt(np.sum((a*a)[ok])*np.sum((b*b)[ok])))
    return np.round(out,2)
bs=0.10
x0,y0=np.nanmin(xy[...,0]),np.nanmin(xy[...,1])
ix=((xy[...,0]-x0)/bs).astype(int); iy=((xy[...,1]-y0)/bs).astype(int)
nb=ix.max()+1; key=iy*nb+ix
def binmeans(val,frames_sel):
    s=np.zeros(key.max()+1);n=np.zeros(key.max()+1)
    for i in frames_sel:
        ok=~np.isnan(val[i]); np.add.at(s,key[i][ok],val[i][ok]); np.add.at(n,key[i][ok],1)
    return s,n
import random
idx=list(range(N))
for name,val,unit in (('raw',res,'raw'),('height',hres,'mm')):
    # remove image pattern (16px cells over all frames) first
    cm=np.nanmean(val.reshape(N,H//16,16,W//16,16),axis=(0,2,4))
    pat=np.repeat(np.repeat(cm,16,0),16,1)
    v=val-pat[None]
    print(name,'total rms',np.nanstd(val),'image pattern rms',np.nanstd(cm),'after',np.nanstd(v))
    print(' autocorr all', autocorr(val[:, :, :]))
    print(' autocorr minus image pattern', autocorr(v))
    for trial in range(2):
        random.seed(trial); random.shuffle(idx)
        A,B=idx[:N//2],idx[N//2:]
        sa,na=binmeans(v,A); sb,nb_=binmeans(v,B)
        ok=(na>2000)&(nb_>2000)
        ma=sa[ok]/na[ok]; mb=sb[ok]/nb_[ok]
        print(' world bins',ok.sum(),'corr halves',np.round(np.corrcoef(ma,mb)[0,1],3),'rms a,b',np.round(ma.std(),3),np.round(mb.std(),3))
    s,n=binmeans(v,range(N)); rel=np.where(n>0,s/np.maximum(n,1),0)
    v2=v-np.where(np.isnan(v),np.nan,rel[key])
    print(' relief rms (bins>2000)',np.std(rel[n>2000]),' after removing relief rms',np.nanstd(v2))
    print(' autocorr minus pattern and relief',autocorr(v2))
    c=cellmap(v2); print(' 16px cell scatter', np.nanstd(c))
