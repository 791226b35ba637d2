"""What the docs site generates at build time (mkdocs hooks): the configuration reference and the benchmarks page."""
