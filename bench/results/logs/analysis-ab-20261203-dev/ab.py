import json,subprocess,sys,glob,os,statistics
probs=sys.argv[1]; rounds=int(sys.argv[2]); bins=sys.argv[3:]
res={b:{} for b in bins}
for r in range(rounds):
    for b in bins:
        d=f"/tmp/ab/res_{os.path.basename(b)}_{r}"
        subprocess.run(["rm","-rf",d])
        subprocess.run([b,"--problems",probs,"--matching","--umfpack","--no-cholmod","--ordering","amd","--threads","1","--repeat","11","--tag","ab","--results-dir",d],capture_output=True)
        f=glob.glob(d+"/*.json")[0]; j=json.load(open(f))
        for row in j["rows"]:
            p=os.path.basename(row["problem"]).replace(".mtx","")
            res[b].setdefault(p,[]).append((row["strata"]["analysis_phase_seconds"]*1e3,row["umfpack_phase_ratio"]))
for p in res[bins[0]]:
    line=p
    for b in bins:
        v=res[b][p]
        line+=f" | {os.path.basename(b)}: {statistics.median(x[0] for x in v):.2f} ms ratio {statistics.median(x[1] for x in v):.2f} ({min(x[1] for x in v):.2f}-{max(x[1] for x in v):.2f})"
    print(line)
