"""What a run's numbers say, pure of devices: the statistics of the readings, the
model the data can tell (``model_choice``), the verification's verdict and how many
cycles it needs (``sizing``), the accuracy at the tool (``accuracy_statement``,
``compensated``), the uncertainty budget (``run_budget``), the lost motion
(``reversal``) and what the station knows of each joint's positioning error
(``joints``). The engine calls it; nothing here moves an axis."""
