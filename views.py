import numpy as np, sys
from PIL import Image, ImageDraw
a=np.fromfile('/tmp/colon-a.u8',dtype=np.uint8).reshape(321,512,512)  # k j i
cl=np.loadtxt('/tmp/cl.txt')  # i j k
def view(axis, flipud, coords, name, scale):
    occ=a.any(axis=axis); first=np.argmax(a,axis=axis).astype(float)
    img=np.where(occ,255-first*0.4,0).astype(np.uint8)
    h,w=img.shape
    if flipud: img=img[::-1]
    im=Image.fromarray(img).convert('RGB').resize((int(w*scale[0]),int(h*scale[1])))
    d=ImageDraw.Draw(im)
    pts=[]
    for p in cl:
        x,y=p[coords[0]],p[coords[1]]
        if flipud: y=h-1-y
        pts.append((x*scale[0],y*scale[1]))
    d.line(pts,fill=(255,0,0),width=3)
    for q,c in ((pts[0],(0,255,0)),(pts[-1],(0,0,255))):
        d.ellipse([q[0]-6,q[1]-6,q[0]+6,q[1]+6],fill=c)
    for t in range(0,len(pts),100):
        d.text(pts[t],str(t),fill=(255,255,0))
    return im
c=view(1,True,(0,2),'cor',(1,1.52))
s=view(2,True,(1,2),'sag',(1,1.52))
out=Image.new('RGB',(1024,488)); out.paste(c,(0,0)); out.paste(s,(512,0)); out.save('/tmp/views.png')
