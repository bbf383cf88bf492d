"""The intermittent OWC link of Cai et al.: the vibrating-link simulator, the estimator session."""
