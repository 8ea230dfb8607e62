"""The parts of ``benchmarks/real_recordings.py`` (the driver: cases, command line, page):
the records read (:mod:`.records`), the plain reference fits (:mod:`.references`), one
diagnosis as a table row with the acceptance targets (:mod:`.rows`), the cases
(:mod:`.cases`) and the zigzag classes fitted on one and predicting the others
(:mod:`.zigzag_classes`)."""
