"""Vehicle and string models: nonlinear HDV car-following (:mod:`.hdv`), the linearised LCC
state spaces (:mod:`.linear`) and static LCC feedback (:mod:`.feedback`)."""
