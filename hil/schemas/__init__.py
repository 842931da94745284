"""JSON Schemas (draft 2020-12) of the files emacheck writes: result.json, serv.json, diagnosis.json,
commission.json."""
