"""Analysis of linear LCC systems: controllability (:mod:`.controllability`), control energy
(:mod:`.energy`), head-to-tail transfer functions (:mod:`.transfer`), the global
string-stability verdict (:mod:`.string_stability`) and region maps (:mod:`.regions`)."""
