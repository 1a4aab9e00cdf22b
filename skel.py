import numpy as np, colorsys
from PIL import Image, ImageDraw
a=np.fromfile('/tmp/colon-a.u8',dtype=np.uint8).reshape(321,512,512)
B={}; M=[]
for l in open('/tmp/skel.txt'):
    t=l.split()
    if t[0]=='B': B.setdefault(int(t[1]),[]).append(tuple(map(float,t[2:5])))
    else: M.append(tuple(map(float,t[2:8])))
def view(axis, coords, scale):
    occ=a.any(axis=axis); first=np.argmax(a,axis=axis).astype(float)
    img=np.where(occ,255-first*0.4,0).astype(np.uint8)[::-1]
    h,w=img.shape
    im=Image.fromarray(img).convert('RGB').resize((int(w*scale[0]),int(h*scale[1])))
    d=ImageDraw.Draw(im)
    P=lambda p:(p[coords[0]]*scale[0],(h-1-p[coords[1]])*scale[1])
    for b,pts in B.items():
        c=tuple(int(255*x) for x in colorsys.hsv_to_rgb((b*0.37)%1,1,1))
        d.line([P(p) for p in pts],fill=c,width=3)
        d.text(P(pts[-1]),str(b),fill=c)
        d.text(P(pts[len(pts)//2]),'b%d'%b,fill=(255,255,255))
    for i,m in enumerate(M):
        d.line([P(m[:3]),P(m[3:])],fill=(0,0,0),width=5)
        d.text(P(m[:3]),'m%d'%i,fill=(0,0,0))
    return im
c=view(1,(0,2),(1.5,2.28)); s=view(2,(1,2),(1.5,2.28))
out=Image.new('RGB',(c.width*2,c.height)); out.paste(c,(0,0)); out.paste(s,(c.width,0)); out.save('/tmp/skel.png')
