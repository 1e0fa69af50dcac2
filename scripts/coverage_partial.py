"""Summarise a coverage study's replicate log (`cargo xtask coverage --json PATH` writes
PATH.partial.jsonl as replicates finish) when the study was stopped before its report: coverage
of the central θ intervals with their 1 % binomial acceptance regions, the SBC rank histogram
and its χ² p-value (10 bins), the mean z and ρ's interval. Usage: python3
scripts/coverage_partial.py LOG.jsonl. Not run in CI.
"""
import json,math,statistics as st,sys
rs=[json.loads(l)['modes'][0] for l in open(sys.argv[1])]
n=len(rs); pits=[r['pit'] for r in rs]
def binom_cdf(k,n,p): return sum(math.comb(n,i)*p**i*(1-p)**(n-i) for i in range(0,k+1))
def region(n,p,alpha=0.01):
    lo=0
    while binom_cdf(lo,n,p)<=alpha/2: lo+=1
    hi=n
    while 1-binom_cdf(hi-1,n,p)<=alpha/2: hi-=1
    return lo,hi
def gammainc_upper_reg(a,x):
    # Q(a,x) via series/continued fraction (Numerical Recipes)
    if x<a+1:
        s=1/a; t=s; k=a
        for _ in range(500):
            k+=1; t*=x/k; s+=t
        return 1-s*math.exp(-x+a*math.log(x)-math.lgamma(a))
    b=x+1-a; c=1e300; d=1/b; h=d
    for i in range(1,500):
        an=-i*(i-a); b+=2; d=an*d+b; d=1/d if d else 1e300; c=b+an/c; h*=d*c
    return math.exp(-x+a*math.log(x)-math.lgamma(a))*h
hist=[0]*10
for p in pits: hist[min(int(p*10),9)]+=1
e=n/10; chi=sum((h-e)**2/e for h in hist); pval=gammainc_upper_reg(4.5,chi/2)
print("n",n)
for lvl in (0.5,0.8,0.9,0.95):
    a=(1-lvl)/2; k=sum(a<=p<=1-a for p in pits); lo,hi=region(n,lvl)
    print(f"{lvl}: {k}/{n} = {k/n:.2f}, 1% acceptance region {lo}..{hi}: {'ok' if lo<=k<=hi else 'FAIL'}")
z=[(r['theta_mean']-r['theta_true'])/r['theta_sd'] for r in rs]
print("SBC hist",hist,"chi2 %.2f p %.3f"%(chi,pval))
print("mean z %.2f (t %.2f), z rms %.2f, median sd %.3f"%(st.mean(z), st.mean(z)/(st.stdev(z)/math.sqrt(n)), math.sqrt(st.mean([x*x for x in z])), st.median(r['theta_sd'] for r in rs)))
print("lower half ranks", sum(p<0.5 for p in pits))
print("rho 95%% covered %d/%d, rho mean %.4f"%(sum(abs(r['rho']-r['rho_true'])<=1.96*r['rho_sd'] for r in rs), n, st.mean(r['rho'] for r in rs)))
print("bands normal %.3f tangential %.3f fatigue %.3f"%(st.mean(r['band_normal'] for r in rs), st.mean(r['band_tangential'] for r in rs), st.mean(r['band_fatigue'] for r in rs)))
ratio=[r['force_rmse']['normal_after']/r['force_rmse']['normal_before'] for r in rs]
print("normal RMSE after/before median %.3f"%st.median(ratio))
secs=sorted((round(r['seconds']),round(r['theta_true'],1)) for r in rs); print("seconds min/median/max", secs[0], secs[len(secs)//2], secs[-3:])
