"""The studies built on the engine and its experiments: the CMA-ES search and its logs (`optimize`, `searchlog`),
the plate fit (`fit`), the paper's report and Table I (`report`, `table`), the benchmarks (`bench`) and the
speed-against-accuracy study (`accuracy`). The engine and the experiments never import them."""
