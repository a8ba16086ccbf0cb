"""The run's record as typed models: result.json (:mod:`station.record.result`, its
larger sections in result_accuracy.py, result_sections.py and result_joints.py, their
common parts in result_base.py; a file of an older version read through
:mod:`station.record.migrate`), the journal's records (:mod:`station.record.journal`)
and model.json (:mod:`station.record.model`), with the JSON Schema other tools validate
them against (:mod:`station.record.schema_files`, ``orthocal schema``); result.json's
writer (:mod:`station.record.io`) and its deviation keys' order
(:mod:`station.record.keys`); what a controller is given: the identified machine
(:mod:`station.record.identified`) and the joint tables in its joints
(:mod:`station.record.controller_tables`)."""
