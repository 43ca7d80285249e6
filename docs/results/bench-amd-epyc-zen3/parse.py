import re,sys,json,collections
rounds=[];cur=None
for l in open(sys.argv[1]):
    if l.startswith('round'):
        cur={'hdr':l.strip()};rounds.append(cur);continue
    if l.startswith('end'):
        cur['end']=l.strip();continue
    m=re.match(r'(.*?) (\{.*\}) CPU ([\d.]+) ([\d.]+)',l)
    if not m or cur is None: continue
    k=m.group(1);j=json.loads(m.group(2));cpu=float(m.group(3))+float(m.group(4))
    cur[k]=(j,cpu)
for r in rounds:
    print(r['hdr'],'|',r.get('end',''))
    g=lambda k:r.get(k)
    try:
        for who in ['old','new']:
            w=g(f'sac256 {who} 300')[0]['ms_per_update']; c=(g(f'sac256 {who} 300')[1]-g(f'sac256 {who} 50')[1])/250*1000
            r[f's_{who}']=(w,c)
        tw=g('sac256 torch 200')[0]['ms_per_update']; tc=(g('sac256 torch 200')[1]-g('sac256 torch 50')[1])/150*1000
        print(f"  SAC h256: old {r['s_old'][0]:.2f} ms wall / {r['s_old'][1]:.2f} ms CPU; new {r['s_new'][0]:.2f} / {r['s_new'][1]:.2f}; torch {tw:.2f} / {tc:.2f}; ratio new wall {tw/r['s_new'][0]:.2f}x CPU {tc/r['s_new'][1]:.2f}x; old wall {tw/r['s_old'][0]:.2f}x CPU {tc/r['s_old'][1]:.2f}x; floor 5.62 ms: new CPU {r['s_new'][1]/5.62:.2f}x")
    except Exception as e: print('  sac incomplete',e)
    try:
        d={}
        for who,a,b in [('old',6000,3000),('new',6000,3000),('sb3',5000,2000)]:
            w=g(f'ddpg {who} {a}')[0]['steps_per_sec']; c=3000/(g(f'ddpg {who} {a}')[1]-g(f'ddpg {who} {b}')[1])
            d[who]=(w,c)
        print(f"  DDPG: old {d['old'][0]:.0f} wall / {d['old'][1]:.0f} CPU steps/s; new {d['new'][0]:.0f} / {d['new'][1]:.0f}; sb3 {d['sb3'][0]:.1f} / {d['sb3'][1]:.1f}; ratio new wall {d['new'][0]/d['sb3'][0]:.1f}x CPU {d['new'][1]/d['sb3'][1]:.1f}x; old wall {d['old'][0]/d['sb3'][0]:.1f}x CPU {d['old'][1]/d['sb3'][1]:.1f}x")
    except Exception as e: print('  ddpg incomplete',e)
    for who in ['old','new']:
        try:
            s=g(f'sac64 {who}')[0]['ms_per_update']; c2=g(f'crossq64-256 {who}')[0]['ms_per_update']; c10=g(f'crossq64-1024 {who}')[0]['ms_per_update']
            print(f"  {who}: SAC h64 {s:.3f} ms, CrossQ actor 64 critics 256 {c2:.2f} ms ({c2/s:.1f}x), critics 1024 {c10:.1f} ms ({c10/s:.0f}x)")
        except Exception as e: print('  crossq incomplete',who,e)
