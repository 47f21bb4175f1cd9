"""Human and machine readable output: terminal summary, markdown, JSON, JUnit, HTML."""
