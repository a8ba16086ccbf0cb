"""The statement of the machine (docs/design.md, "The statement of the machine"): built
once, at the end of a run, from one snapshot of its rounds (:class:`Rounds`): every
quantity with one value and one 95 % uncertainty (Type A and B, GUM), the decision
table's word on each, the advice that follows, and the run's end (the loop's verdict,
acceptance) read from them. Views render the record it fills and compute nothing."""
