#!/usr/bin/env python3
"""Background models against the plain calibration rule (docs/experiments.md, "Calibration").

Usage: background.py PREFIX CAL_SEEDS TEST_SEEDS DIST, in the experiments directory: reads
PREFIX_free_sSEED_DIST.npy (gradient images of defect-free parts), PREFIX_DIST.npy and
PREFIX.truth.npy. For the plain magnitude, the magnitude less a per-column background (median
of each column over the calibration parts) and less a per-position background (mean over them),
applies the rule max + 3 * 1.4826 * MAD on the calibration parts and counts positions at or
above it on the unseen parts and on the defective part. Standard library only."""
import struct, sys, array, ast, statistics
def load(p):
    b=open(p,'rb').read()
    hl=struct.unpack('<H',b[8:10])[0]; h=ast.literal_eval(b[10:10+hl].decode())
    a=array.array('d'); a.frombytes(b[10+hl:]); r,c=h['shape'][:2]
    return r,c,[a[i*3+2] for i in range(r*c)]
def loadmask(p):
    b=open(p,'rb').read(); hl=struct.unpack('<H',b[8:10])[0]; return [x!=0 for x in b[10+hl:]]
def med(v):
    v=sorted(v); n=len(v); return v[n//2] if n%2 else (v[n//2-1]+v[n//2])/2
def rule(v,k=3):
    m=med(v); mad=med([abs(x-m) for x in v]); return max(v)+k*1.4826*mad, max(v), m, mad
pre, cal, test = sys.argv[1], sys.argv[2].split(','), sys.argv[3].split(',')
dist=sys.argv[4]
R=[load(f"{pre}_free_s{s}_{dist}.npy") for s in cal]
r,c,_=R[0]
# per-column background: median over all rows of all calibration parts
bg=[med([x[2][i*c+j] for x in R for i in range(r)]) for j in range(c)]
# per-position background: mean over calibration parts
pp=[sum(x[2][k] for x in R)/len(R) for k in range(r*c)]
for name,f in [("plain",lambda v,k: v[k]),("column",lambda v,k: v[k]-bg[k%c]),("position",lambda v,k: v[k]-pp[k])]:
    allv=[f(x[2],k) for x in R for k in range(r*c)]
    thr,mx,m,mad=rule(allv)
    fo=[]
    for s in test:
        _,_,v=load(f"{pre}_free_s{s}_{dist}.npy"); fo.append(sum(1 for k in range(r*c) if f(v,k)>=thr))
    _,_,v=load(f"{pre}_{dist}.npy"); t=loadmask(f"{pre}.truth.npy")
    hit=sum(1 for k in range(r*c) if t[k] and f(v,k)>=thr); fa=sum(1 for k in range(r*c) if (not t[k]) and f(v,k)>=thr)
    # margin of thr over the background spread
    print(f"{pre} {dist} {name:8s} thr {thr:.4g} (max {mx:.4g} median {m:.4g} MAD {mad:.3g}); positions >= thr on unseen free parts {fo}; defective part: truth positions >= thr {hit}/{sum(t)}, others {fa}")
