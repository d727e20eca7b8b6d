"""The identification methods, one set for every plant: IDIM-LS, DIDIM and the three-step procedure
(:mod:`.identification`), the output-error methods (:mod:`.oe`), DIDIM's iterations and safeguards written once
(:mod:`.didim_loop`), the friction law's search (:mod:`.friction_law`) and a robot's plants, base parameters and
payload (:mod:`.robot`)."""
