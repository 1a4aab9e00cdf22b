import numpy as np, dijkstra3d, time
from PIL import Image
a=np.fromfile('/tmp/colon-a.u8',dtype=np.uint8).reshape(321,512,512)
src=np.loadtxt('/tmp/cl.txt')[0]  # i j k
s=(int(round(src[2])),int(round(src[1])),int(round(src[0])))
t=time.time()
d=dijkstra3d.euclidean_distance_field(a.astype(bool), source=s, anisotropy=(1.25,0.820312,0.820312))
print('dijkstra3d', time.time()-t, 'max', d[np.isfinite(d)&(a>0)].max())
d[a==0]=np.inf
np.save('/tmp/geo.npy', d.astype(np.float32))
def cmap(x):
    x=np.clip(x,0,1)
    r=np.clip(1.5-abs(4*x-3),0,1); g=np.clip(1.5-abs(4*x-2),0,1); b=np.clip(1.5-abs(4*x-1),0,1)
    return np.stack([r,g,b],-1)
mx=d[np.isfinite(d)].max()
def proj(axis, flip):
    occ=a.any(axis=axis); first=np.argmax(a,axis=axis)
    idx=np.expand_dims(first,axis)
    val=np.take_along_axis(d,idx,axis).squeeze(axis)
    img=(cmap(val/mx)*255*occ[...,None]).astype(np.uint8)
    if flip: img=img[::-1]
    return Image.fromarray(img)
c=proj(1,True).resize((512,488)); sg=proj(2,True).resize((512,488))
# also from posterior (flip j)
ap=a[:,::-1,:]; 
out=Image.new('RGB',(1024,488)); out.paste(c,(0,0)); out.paste(sg,(512,0)); out.save('/tmp/geo.png')
