"""The five classifiers of the paper as scikit-learn estimators (``classifiers``, with the
evolutionary SVM in ``evolutionary_svm``) and touch fusion: calibrated posteriors multiplied over
distinct touches (``fusion``)."""
