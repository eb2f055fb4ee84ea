"""The twin: scenario -> MuJoCo model -> posed bodies -> instruments -> procedures -> dataset + truth/."""
