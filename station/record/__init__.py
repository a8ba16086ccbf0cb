"""The run's record as typed models: result.json (:mod:`station.record.result`) and
the journal's records (:mod:`station.record.journal`), with the JSON Schema other
tools validate them against (:mod:`station.record.schema`, ``orthocal schema``)."""
