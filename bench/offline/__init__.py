"""Systems that run outside posbench: the queries folder ``bench queries`` writes
(:mod:`~posbench.offline.queries_folder`) and the answers ``bench score`` reads back
(:mod:`~posbench.offline.answers`, scored by :mod:`~posbench.offline.answer_scoring`)."""
