import re, os
S='/work/runs/s17'
def read(path):
    if not os.path.exists(path): return None
    t=open(path).read()
    m=re.search(r'relative rotation error: ([\d.]+)°', t); f=re.search(r'learned fx ([\d.]+) .*reference ([\d.]+)', t)
    if not m or not f: return None
    return float(m.group(1)), 100*(float(f.group(1))/float(f.group(2))-1)
A0={'plain':(0.96,-6.0),'lookat':(1.77,-5.4),'deep':(0.54,-6.1),'few':(1.28,-6.3),'shiny':(0.89,-5.9),'sweep':(8.49,-2.7)}
rows=[]
for s in ['plain','lookat','deep','few','shiny','sweep']:
    c=[A0[s], read(f'{S}/zooB/{s}.log'), read(f'{S}/zooM/{s}.log'), read(f'{S}/seed1/A_{s}.log'), read(f'{S}/seed1/B_{s}.log'), read(f'{S}/seed1/M_{s}.log')]
    fmt=lambda x: '–' if x is None else f'{x[0]:.2f} ({x[1]:+.1f}%)'
    rows.append(f'| {s} | ' + ' | '.join(fmt(x) for x in c) + ' |')
print('| scene | seed 0: learned box | fixed box | box 0.8× | seed 1: learned box | fixed box | box 0.8× |')
print('|---|---|---|---|---|---|---|')
print('\n'.join(rows))
