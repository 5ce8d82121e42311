"""The five classifiers of the paper as scikit-learn estimators (``classifiers``, with the
evolutionary SVM in ``evolutionary_svm``, its dual solved by the evolution strategy of
``evolution_strategy``) and touch fusion: calibrated posteriors multiplied over
distinct touches (``fusion``)."""
